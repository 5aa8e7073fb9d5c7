"""Check a GPU against the CPU: run one config with `device: cpu` and with `device: cuda`, each in
its own copy of the workflow, and print per stage the largest relative difference of its vector
edges against the stage's tolerance, whether the findings' decisions agree, and each rule's
seconds on both (`tacgen_lib.io.run_compare`; docs/cluster.md, "Checking a GPU against the CPU").

    .venv/bin/python tools/device_check.py                          # config/test.yaml, cpu vs cuda
    .venv/bin/python tools/device_check.py --devices cpu cpu        # the same check on two CPU runs
    .venv/bin/python tools/device_check.py --compare RUN_A RUN_B    # two finished runs, nothing run
    .venv/bin/python tools/device_check.py -- results/features/sim_paired/vision.parquet
                                                                    # Snakemake arguments (targets)

Runs go to --work (default results/device_check/, under this repository's git-ignored results/),
one folder per device, each a fresh copy of the workflow. Exit status 0 where every stage is
within its tolerance and the decisions agree (or the runs did not produce them), else 1.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tacgen_lib.io.run_compare import (  # noqa: E402 - after the repository is on the path
    DecisionComparison,
    StageDifference,
    compare_decisions,
    copy_workflow,
    stage_differences,
)


def fresh_workflow(dest: Path) -> Path:
    """A fresh copy of the workflow in `dest` (removed first where it exists)."""
    if dest.exists():
        shutil.rmtree(dest)
    return copy_workflow(ROOT, dest)


def run_folders(work: Path, devices: Sequence[str]) -> list[Path]:
    """One folder per run under `work`, named for its device (cpu-1, cpu-2 where both are)."""
    if len(set(devices)) == len(devices):
        return [work / d for d in devices]
    return [work / f"{d}-{i}" for i, d in enumerate(devices, start=1)]


def snakemake_command(device: str, configfile: str, cores: int, extra: Sequence[str]) -> list[str]:
    """The Snakemake command of one run (in its copy of the workflow)."""
    return [
        sys.executable,
        "-m",
        "snakemake",
        "--cores",
        str(cores),
        "--configfile",
        configfile,
        "--config",
        f"device={device}",
        *extra,
    ]


def run(folder: Path, command: list[str]) -> float:
    """Run `command` in a fresh copy of the workflow in `folder`; its wall seconds. The copy's
    library comes first on PYTHONPATH, so every job, also those the preloaded interpreter
    runs (it does not put the working directory on its path), uses the copy's code. Output
    goes to folder/device_check.log; a failure stops the check naming it."""
    fresh_workflow(folder)
    log = folder / "device_check.log"
    path = os.pathsep.join(p for p in (str(folder), os.environ.get("PYTHONPATH", "")) if p)
    started = time.perf_counter()
    with log.open("w") as out:
        proc = subprocess.run(
            command,
            cwd=folder,
            stdout=out,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONPATH": path},
        )
    seconds = time.perf_counter() - started
    if proc.returncode != 0:
        tail = log.read_text()[-3000:]
        raise SystemExit(f"device_check: {' '.join(command[2:])} failed in {folder}:\n{tail}")
    return seconds


def stage_table(stages: list[StageDifference]) -> str:
    """The per-stage lines: stage, columns compared, largest relative difference, tolerance,
    within, and where the largest is."""
    if not stages:
        return "no vector edges in either run"
    rows = [("stage", "columns", "largest rel. diff", "tolerance", "within", "where")]
    for s in stages:
        w = s.worst
        where = w.note or (
            "equal in every row" if w.max_rel == 0 else f"{w.edge} [{w.column}] {w.worst_key!r}"
        )
        rows.append(
            (
                s.stage,
                str(s.columns),
                "inf" if math.isinf(s.max_rel) else f"{s.max_rel:.3g}",
                f"{s.tolerance:g}",
                "yes" if s.within else "NO",
                where,
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    return "\n".join(
        "  ".join(c.ljust(widths[i]) for i, c in enumerate(r[:5])) + "  " + r[5] for r in rows
    )


def decisions_line(found: DecisionComparison | None) -> str:
    """One line on the findings' decisions of both runs, then one per decision that differs
    or that one run states alone, with both runs' values."""
    if found is None:
        return "decisions: not produced by this run"
    if found.agree:
        return f"decisions: all {found.decisions} agree"
    parts = []
    for label, ids in (("differ", found.differ), ("only in a", found.only_a)):
        if ids:
            parts.append(f"{len(ids)} {label}: {', '.join(ids)}")
    if found.only_b:
        parts.append(f"{len(found.only_b)} only in b: {', '.join(found.only_b)}")
    return "\n".join([f"decisions: of {found.decisions}, " + "; ".join(parts), *found.lines])


def seconds_table(run_a: Path, run_b: Path, labels: Sequence[str], top: int = 20) -> str:
    """Each rule's job wall seconds summed from its benchmark files in both runs (the rules
    with the most seconds in run a first): what calibrates a GPU class's rate."""
    from tacgen_lib.runtime.benchmarks import benchmark_table

    a = (
        benchmark_table(run_a / "results" / "benchmarks")
        .groupby("rule")["wall"]
        .agg(["sum", "count"])
    )
    b = benchmark_table(run_b / "results" / "benchmarks").groupby("rule")["wall"].sum()
    if a.empty:
        return "seconds: no benchmark files"
    rows = [("rule", "jobs", f"{labels[0]} s", f"{labels[1]} s")]
    for rule, row in a.sort_values("sum", ascending=False).head(top).iterrows():
        other = b.get(rule)
        rows.append(
            (
                str(rule),
                str(int(row["count"])),
                f"{row['sum']:.1f}",
                "-" if other is None else f"{other:.1f}",
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    return "\n".join("  ".join(c.ljust(widths[i]) for i, c in enumerate(r)) for r in rows)


def report(run_a: Path, run_b: Path, labels: Sequence[str]) -> tuple[str, bool]:
    """The check's text and whether it passed (every stage within, decisions agree)."""
    stages = stage_differences(run_a, run_b)
    decisions = compare_decisions(run_a, run_b)
    ok = all(s.within for s in stages) and (decisions is None or decisions.agree)
    text = "\n".join(
        [
            f"run a: {labels[0]} ({run_a})",
            f"run b: {labels[1]} ({run_b})",
            stage_table(stages),
            decisions_line(decisions),
            seconds_table(run_a, run_b, labels),
            f"device check: {'ok' if ok else 'FAILED'}",
        ]
    )
    return text, ok


def main(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--configfile", default="config/test.yaml")
    parser.add_argument("--devices", nargs=2, default=["cpu", "cuda"], metavar=("A", "B"))
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--work", type=Path, default=ROOT / "results" / "device_check")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("RUN_A", "RUN_B"))
    parser.add_argument("extra", nargs="*", help="after --: more Snakemake arguments")
    args = parser.parse_args(argv)
    if args.compare:
        run_a, run_b = args.compare
        labels = [str(run_a), str(run_b)]
    else:
        run_a, run_b = run_folders(args.work.resolve(), args.devices)
        labels = list(args.devices)
        for folder, device in ((run_a, args.devices[0]), (run_b, args.devices[1])):
            command = snakemake_command(device, args.configfile, args.cores, args.extra)
            seconds = run(folder, command)
            print(f"device {device}: {args.configfile} in {seconds:.0f} s ({folder})", flush=True)
    text, ok = report(run_a, run_b, labels)
    print(text)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
