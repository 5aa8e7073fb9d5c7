"""Snakemake `benchmark:` files: the one source of a job's run time (never an edge's contents).

A benchmark TSV has one row per repeat with wall seconds `s`, `cpu_time` and memory columns.
Snakemake samples memory and CPU sparsely, and ever more rarely as a job runs
(snakemake#851, #2147), so `cpu_time` and `max_rss` of long jobs are under-reported; wall
`s` is reliable. Where a figure needs peak memory or CPU time, the job measures it itself and
writes it beside the benchmark, not into an edge.

A job run in the preloaded interpreter (`tacgen_lib.runtime.preload`) does its work outside the
process tree Snakemake measures: its exact CPU time and peak RSS (from `wait4`) are in
`<benchmark>.usage.json` beside the file, and `read_benchmark` adds them in.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from tacgen_lib.runtime.preload import usage_path

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "Benchmark",
    "read_benchmark",
    "write_benchmark",
    "benchmark_seconds",
    "benchmark_table",
    "cpu_label",
    "cpuinfo",
]


@dataclass(frozen=True)
class Benchmark:
    """One job's benchmark: wall seconds, CPU seconds (sparsely sampled) and peak RSS (MB),
    each the mean over the file's repeats."""

    wall: float
    cpu: float
    max_rss_mb: float


def _read(path: str | os.PathLike[str]) -> pd.DataFrame:
    import pandas as pd  # here, not at the top: a sampling job writes its cells' files without it

    try:
        table = pd.read_csv(path, sep="\t")
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise ValueError(f"{path}: not a readable Snakemake benchmark file ({exc})") from exc
    if "s" not in table.columns or table.empty:
        raise ValueError(
            f"{path}: benchmark file has no 's' column or no rows (columns: {list(table.columns)})"
        )
    return table


def _mean(table: pd.DataFrame, column: str) -> float:
    import pandas as pd

    if column not in table.columns:
        return float("nan")
    return float(pd.to_numeric(table[column], errors="coerce").mean())


def read_benchmark(path: str | os.PathLike[str]) -> Benchmark:
    """The job's wall, CPU seconds and peak RSS from its benchmark TSV; for a job run in the
    preloaded interpreter, its CPU seconds are the job process's (Snakemake's sample) plus the
    forked copy's that did the work, its peak RSS the larger of the two."""
    table = _read(path)
    cpu, rss = _mean(table, "cpu_time"), _mean(table, "max_rss")
    usage_file = usage_path(path)
    if usage_file.exists():
        try:
            usage = json.loads(usage_file.read_text())
            copy_cpu, copy_rss = float(usage["cpu_s"]), float(usage["max_rss_mb"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"{usage_file}: not a readable job usage file ({exc})") from exc
        cpu = copy_cpu + (cpu if cpu == cpu else 0.0)
        rss = max(copy_rss, rss) if rss == rss else copy_rss
    import pandas as pd

    return Benchmark(
        wall=float(pd.to_numeric(table["s"], errors="raise").mean()),
        cpu=cpu,
        max_rss_mb=rss,
    )


def write_benchmark(path: str | os.PathLike[str], *, wall: float, cpu: float) -> None:
    """A benchmark file in Snakemake's format (`s`, `h:m:s`, `cpu_time`) for a part of a job
    that times itself: one sampling cell of a generator's sampling job, whose cells share the
    job's benchmark. `read_benchmark` reads it like Snakemake's own; written atomically."""
    path = Path(path)
    h, rest = divmod(int(wall), 3600)
    text = f"s\th:m:s\tcpu_time\n{wall:.4f}\t{h}:{rest // 60:02d}:{rest % 60:02d}\t{cpu:.4f}\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def benchmark_seconds(path: str | os.PathLike[str]) -> float:
    """Wall time of a job from its Snakemake benchmark TSV (column ``s``; mean over repeats)."""
    return read_benchmark(path).wall


def benchmark_table(root: str | os.PathLike[str] = "results/benchmarks") -> pd.DataFrame:
    """Every benchmark file below `root`, one row each: `rule` (the first folder, which is the
    rule's name by the workflow's convention), `job` (the rest of the path, without `.tsv`),
    `path`, `wall`, `cpu`, `max_rss_mb`. Empty (with those columns) if `root` does not exist."""
    import pandas as pd

    root = Path(root)
    rows = []
    for path in sorted(root.rglob("*.tsv")) if root.is_dir() else []:
        rel = path.relative_to(root).with_suffix("")
        rule = rel.parts[0]
        job = "/".join(rel.parts[1:]) or rule
        b = read_benchmark(path)
        rows.append((rule, job, str(path), b.wall, b.cpu, b.max_rss_mb))
    return pd.DataFrame(rows, columns=["rule", "job", "path", "wall", "cpu", "max_rss_mb"])


def cpuinfo() -> dict[str, str]:
    """/proc/cpuinfo's fields, each key's first value (the first CPU's); empty where there is
    no /proc/cpuinfo."""
    fields: dict[str, str] = {}
    path = Path("/proc/cpuinfo")
    if path.exists():
        for line in path.read_text().splitlines():
            key, _, value = line.partition(":")
            fields.setdefault(key.strip(), value.strip())
    return fields


def cpu_label() -> str:
    """The CPU a figure was measured on: model, core count and widest x86 vector extension
    (the same code runs markedly slower on the 2-core class without AVX-512)."""
    info = cpuinfo()
    model, flags = info.get("model name", "unknown CPU"), set(info.get("flags", "").split())
    vector = next((f for f in ("avx512f", "avx2", "avx", "sse4_2") if f in flags), "-")
    return f"{model}, {os.cpu_count()} cores, vector {vector}"
