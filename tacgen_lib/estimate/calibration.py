"""Per-unit costs of each rule, fitted on benchmark files, and the calibration shipped with the
project.

A calibration is a table of points, one per benchmarked job: its cost class and units
(tacgen_lib.estimate.units) and its measured wall seconds, labelled with the run (config) and the
CPU it was measured on. `fit_costs` turns points into one `overhead + per_unit × units` line
per cost class by non-negative least squares. The shipped calibration lives in
`config/cost_calibration/` (`points.csv` and `runs.csv`, the runs' total wall times, which
calibrate the workflow's own overhead: DAG building and per-job bookkeeping).

Regenerate it after a change to the default config, a rule's code or its `UNITS` line, from
the benchmark folders of finished cold runs (each with the config it ran and its total wall):

    .venv/bin/python -m tacgen_lib.estimate.calibration --run test RUNDIR_TEST --run default RUNDIR_DEFAULT

where each RUNDIR is a workflow directory after a cold `snakemake --cores 2` run (its config
and wall time are read from its newest finished Snakemake log, `.snakemake/log/`).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.estimate.dag import DagJob, dag_jobs
from tacgen_lib.estimate.flops import flop_seconds
from tacgen_lib.estimate.schedule import Task, list_schedule, local_machine
from tacgen_lib.estimate.units import job_units
from tacgen_lib.runtime.benchmarks import cpu_label, read_benchmark

__all__ = [
    "CALIBRATION_COLUMNS",
    "RUN_COLUMNS",
    "SHIPPED",
    "Calibration",
    "CostLine",
    "calibration_points",
    "fit_costs",
    "load_calibration",
    "write_calibration",
    "MissingCalibrationError",
    "load_factors",
    "unshared_seconds",
    "idle_ratio",
    "last_run",
    "RunLog",
]

SHIPPED = Path(__file__).resolve().parents[2] / "config" / "cost_calibration"
CALIBRATION_COLUMNS = [
    "run",
    "cpu",
    "cost_class",
    "rule",
    "job",
    "threads",
    "units",
    "flops",
    "wall",
    "cpu_s",
]
RUN_COLUMNS = ["run", "config", "cpu", "jobs", "cores", "wall", "makespan", "load", "note"]


class MissingCalibrationError(KeyError):
    """A cost class of the DAG has no point in the calibration."""

    def __str__(self) -> str:
        return str(self.args[0])


@dataclass(frozen=True)
class CostLine:
    """Predicted wall seconds of a job of one cost class: `overhead + per_unit × units`.

    `n` points, `spread` their root-mean-square relative residual, `identified` False when the
    points' units were too close to tell overhead from per-unit cost (the line is then flat at
    their mean: a lower bound for larger jobs, see `fit_costs`)."""

    cost_class: str
    overhead: float
    per_unit: float
    n: int
    spread: float
    identified: bool

    def seconds(self, units: float) -> float:
        return self.overhead + self.per_unit * units


@dataclass(frozen=True)
class Calibration:
    """Points and run totals, and where they came from (`source`: a sentence for the output)."""

    points: pd.DataFrame
    runs: pd.DataFrame
    source: str

    @property
    def cpus(self) -> list[str]:
        return sorted(set(self.points["cpu"]))


def calibration_points(
    jobs: Sequence[DagJob],
    config: dict[str, Any],
    benchmarks: str | os.PathLike[str],
    *,
    run: str,
    cpu: str,
    benchmark_prefix: str = "results/benchmarks",
) -> pd.DataFrame:
    """One point per job of the DAG whose benchmark file exists below `benchmarks` (the job's
    benchmark path with `benchmark_prefix` replaced by `benchmarks`): cost class and units of
    the job under `config` (the config that run used), threads, measured wall seconds."""
    root = Path(benchmarks)
    rows = []
    for job in jobs:
        if not job.runs or job.benchmark is None:
            continue
        rel = os.path.relpath(job.benchmark, benchmark_prefix)
        path = root / rel
        if not path.exists():
            continue
        cost_class, units, flops = job_units(job.rule, job.config_of(config), job.wildcards)
        b = read_benchmark(path)
        rows.append((run, cpu, cost_class, job.rule, rel, job.threads, units, flops, b.wall, b.cpu))
    return pd.DataFrame(rows, columns=CALIBRATION_COLUMNS)


#: Wall / CPU seconds of a job on idle cores, by threads: a single-threaded job waits for
#: nothing but a little I/O (its benchmark files' wall against CPU seconds show it); each
#: further thread adds most of a core (benchmarks/bench_align.py with --threads 1 and
#: --threads 2 measures the heads' speed-up from a second thread).
IDLE_WALL_PER_CPU = 1.2
EXTRA_THREAD_CORES = 0.8


def idle_ratio(threads: int) -> float:
    """Wall / CPU seconds of a `threads`-thread job on idle cores."""
    return IDLE_WALL_PER_CPU / (1.0 + EXTRA_THREAD_CORES * (max(1, int(threads)) - 1))


def unshared_seconds(points: pd.DataFrame) -> pd.Series:
    """Each job's wall as on idle cores: its wall, or its CPU seconds × `idle_ratio(threads)`
    when that is less (the job waited for cores other processes held). Jobs measured under
    different loads land on one scale. CPU seconds of jobs longer than ~15 s are sampled
    sparsely (snakemake#851) and read low by up to ~30 s: the idle wall of a long job measured
    under load is under-estimated by as much."""
    ratio = points["threads"].map(idle_ratio)
    idle = points["cpu_s"] * ratio
    use = (points["cpu_s"] > 0) & (idle < points["wall"])
    return points["wall"].where(~use, idle)


def load_factors(points: pd.DataFrame) -> dict[str, float]:
    """Each run's load factor: its measured over its idle seconds (`unshared_seconds`), median
    over its jobs (>= 1). ~1 on idle cores; 6-10 with a dozen other jobs sharing 2 cores."""
    ratio = (points["wall"] / unshared_seconds(points)).groupby(points["run"]).median()
    return {run: max(1.0, float(ratio.get(run, 1.0))) for run in points["run"].unique()}


#: Units of a class's points must span at least this factor to fit a per-unit cost.
MIN_UNITS_SPAN = 2.0


def fit_costs(points: pd.DataFrame, *, unshared: bool = True) -> dict[str, CostLine]:
    """One `CostLine` per cost class by non-negative least squares of wall (less the FLOP
    term, `flops.flop_seconds`) on [1, units]; with
    `unshared`, each job's wall is first its idle wall (`unshared_seconds`), so runs measured
    under different loads fit one line, in seconds on idle cores.

    Least squares on relative error (each point weighted by 1 / its wall), so a 2-s job and a
    300-s job count alike. A class whose points span less than a factor `MIN_UNITS_SPAN` of
    units cannot separate overhead from per-unit cost (one size measured, or sizes too close
    for the timing noise): its line is flat at the mean (per-unit cost 0, `identified` False),
    so for larger jobs it is a lower bound, flagged in the estimate's table."""
    from scipy.optimize import nnls

    lines: dict[str, CostLine] = {}
    pending = []
    if unshared and len(points):
        points = points.assign(wall=unshared_seconds(points))
    for cost_class, grp in points.groupby("cost_class", sort=True):
        u = grp["units"].to_numpy(float)
        arithmetic = np.array(
            [flop_seconds(f, t) for f, t in zip(grp["flops"], grp["threads"], strict=True)]
        )
        # the FLOP term is charged at the CPU's rate; the line fits what remains
        wall = grp["wall"].to_numpy(float)
        y = np.maximum(wall - arithmetic, 0.0)
        if u.min() > 0 and u.max() / u.min() >= MIN_UNITS_SPAN or u.min() <= 0 < u.max():
            w = 1.0 / np.maximum(wall, 1e-3)
            design = np.column_stack([np.ones_like(u), u]) * w[:, None]
            (a, b), _ = nnls(design, y * w)
            lines[cost_class] = _line(cost_class, a, b, u, y, wall, identified=True)
        else:
            pending.append((cost_class, u, y, wall))
    for cost_class, u, y, wall in pending:
        lines[cost_class] = _line(cost_class, float(y.mean()), 0.0, u, y, wall, identified=False)
    return lines


def _line(cost_class: str, a: float, b: float, u, y, wall, *, identified: bool) -> CostLine:
    pred = a + b * u + (wall - y)  # the line plus the FLOP term, against the measured wall
    spread = float(np.sqrt(np.mean(((pred - wall) / np.maximum(wall, 1e-3)) ** 2)))
    return CostLine(cost_class, float(a), float(b), int(u.size), spread, identified)


def load_calibration(folder: str | os.PathLike[str] = SHIPPED) -> Calibration:
    """The calibration in `folder` (`points.csv`, `runs.csv`); a missing file or column raises
    naming the file."""
    folder = Path(folder)
    tables = []
    for name, columns in (("points.csv", CALIBRATION_COLUMNS), ("runs.csv", RUN_COLUMNS)):
        path = folder / name
        if not path.exists():
            raise FileNotFoundError(
                f"{path}: no calibration here; regenerate it with "
                "`python -m tacgen_lib.estimate.calibration` (see its --help)"
            )
        table = pd.read_csv(path, comment="#")
        missing = [c for c in columns if c not in table.columns]
        if missing:
            raise ValueError(f"{path}: calibration lacks columns {missing}")
        tables.append(table[columns])
    points, runs = tables
    label = ", ".join(
        f"{r.run} ({r.jobs} jobs, {r.wall:.0f} s on {r.cores} cores)" for r in runs.itertuples()
    )
    what = "shipped calibration" if folder.resolve() == SHIPPED.resolve() else "calibration"
    cpus = "; ".join(sorted(set(points["cpu"])))
    source = f"{what} {folder} from runs {label}; CPU: {cpus}"
    return Calibration(points, runs, source)


def write_calibration(
    points: pd.DataFrame, runs: pd.DataFrame, folder: str | os.PathLike[str]
) -> None:
    """Write `points.csv` and `runs.csv` to `folder` (each atomically: temp file + rename)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    header = (
        "# Run-time calibration of tacgen_lib.estimate (one row per benchmarked job / run).\n"
        "# Regenerate: python -m tacgen_lib.estimate.calibration --help\n"
    )
    for name, table, columns in (
        ("points.csv", points, CALIBRATION_COLUMNS),
        ("runs.csv", runs, RUN_COLUMNS),
    ):
        tmp = folder / f".{name}.tmp"
        tmp.write_text(header + table[columns].to_csv(index=False, float_format="%.6g"))
        tmp.replace(folder / name)


def run_calibration(
    configfile: str | os.PathLike[str],
    benchmarks: str | os.PathLike[str],
    *,
    run: str,
    cpu: str | None = None,
    workdir: str | os.PathLike[str] = ".",
    partial: bool = False,
) -> tuple[pd.DataFrame, list[DagJob]]:
    """Points of one finished run: the DAG of `configfile` matched to the files in
    `benchmarks`. Raises if a job of that DAG has no benchmark file there (the folder is not
    a complete run of that config), unless `partial`."""
    jobs, config = dag_jobs([configfile], workdir=workdir)
    points = calibration_points(jobs, config, benchmarks, run=run, cpu=cpu or cpu_label())
    want = sum(1 for j in jobs if j.runs and j.benchmark is not None)
    if len(points) < want and not partial:
        raise ValueError(
            f"{benchmarks}: {want - len(points)} of the {want} jobs of {configfile}'s DAG have no "
            "benchmark file; is this the benchmark folder of a complete run of that config?"
        )
    return points, jobs


def measured_makespan(jobs: Sequence[DagJob], walls: dict[str, float], cores: int) -> float:
    """The list-scheduled wall time of `jobs` on `cores` with their measured seconds (`walls`
    by benchmark path relative to results/benchmarks; 0 for a job without one). A run's total
    wall minus this is the workflow's own overhead (DAG building, per-job bookkeeping)."""
    tasks = [
        Task(
            j.jobid,
            walls.get(os.path.relpath(j.benchmark, "results/benchmarks"), 0.0)
            if j.benchmark
            else 0.0,
            j.threads,
            j.deps,
            j.local,
        )
        for j in jobs
    ]
    return list_schedule(tasks, local_machine(cores)).makespan


@dataclass(frozen=True)
class RunLog:
    """A finished Snakemake run of a directory, from its log in `.snakemake/log/`: the log's
    `path`, the `configfiles` given with `--configfile` (the embedded default left out), and its
    `wall` seconds (the log's start, in its name, to its last write)."""

    path: Path
    configfiles: tuple[str, ...]
    wall: float


def last_run(rundir: str | os.PathLike[str] = ".") -> RunLog | None:
    """The newest Snakemake run of `rundir` that finished every job (its log says "(100%)
    done"); None if there is none. Dry runs, reports and failed runs are skipped."""
    logs = sorted(Path(rundir, ".snakemake", "log").glob("*.snakemake.log"), reverse=True)
    for log in logs:
        text = log.read_text(errors="replace")
        if "(100%) done" not in text:
            continue
        files: tuple[str, ...] = ()
        for line in text.splitlines():
            if line.strip().startswith("Config file(s):"):
                listed = line.split(":", 1)[1]
                names = [n.strip(" '\"[]") for n in listed.split(",")]
                names = [n.removeprefix("PosixPath(").rstrip(")").strip("'\"") for n in names]
                files = tuple(
                    os.path.relpath(n, Path(rundir).absolute()) if os.path.isabs(n) else n
                    for n in names
                    if n and Path(n).name != "config.yaml"
                )
                break
        # the log is named by its local start time; its last write is the run's end
        started = datetime.strptime(log.name.split(".snakemake")[0], "%Y-%m-%dT%H%M%S.%f")
        ended = datetime.fromtimestamp(log.stat().st_mtime)
        return RunLog(log, files, (ended - started).total_seconds())
    return None


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m tacgen_lib.estimate.calibration",
        description="Regenerate the run-time calibration from finished cold runs: each run's "
        "directory holds results/benchmarks and the Snakemake log giving its config and wall.",
    )
    parser.add_argument(
        "--run",
        nargs=2,
        action="append",
        default=[],
        metavar=("NAME", "RUNDIR"),
        help="a finished cold run: a name (test, default) and its workflow directory "
        "(repeat for each run)",
    )
    parser.add_argument(
        "--partial",
        nargs=3,
        action="append",
        default=[],
        metavar=("NAME", "CONFIGFILE", "BENCHMARKS"),
        help="an unfinished run: the jobs with a benchmark file give points, the run no total",
    )
    parser.add_argument("--note", default="", help="conditions of the runs (e.g. machine load)")
    parser.add_argument("--out", default=str(SHIPPED), help="calibration folder (default: shipped)")
    parser.add_argument("--cpu", default=None, help="CPU label (default: this machine's)")
    parser.add_argument("--cores", type=int, default=2, help="cores the runs used (default 2)")
    args = parser.parse_args(argv)
    points, runs = [], []
    for name, rundir in args.run:
        log = last_run(rundir)
        if log is None:
            raise SystemExit(f"{rundir}: no finished Snakemake run in .snakemake/log/")
        configfile = log.configfiles[0] if log.configfiles else "config/config.yaml"
        bench = Path(rundir) / "results" / "benchmarks"
        p, jobs = run_calibration(configfile, bench, run=name, cpu=args.cpu)
        points.append(p)
        measured = dict(zip(p["job"], p["wall"], strict=True))
        span = measured_makespan(jobs, measured, args.cores)
        n_jobs = sum(j.runs for j in jobs)
        cpu = args.cpu or cpu_label()
        load = load_factors(p)[name]
        runs.append((name, configfile, cpu, n_jobs, args.cores, log.wall, span, load, args.note))
        print(
            f"{name}: {configfile}, {len(p)} benchmarked jobs, wall {log.wall:.0f} s ({log.path})"
        )
    for name, configfile, bench in args.partial:
        p, _ = run_calibration(configfile, bench, run=name, cpu=args.cpu, partial=True)
        points.append(p)
        print(f"{name}: {configfile}, {len(p)} benchmarked jobs (partial run, no total)")
    if not points:
        parser.error("give at least one --run or --partial")
    write_calibration(
        pd.concat(points, ignore_index=True), pd.DataFrame(runs, columns=RUN_COLUMNS), args.out
    )
    print(f"wrote {args.out}/points.csv and runs.csv")


if __name__ == "__main__":
    main()
