"""Predict a run: per-rule and total wall time of a config's DAG on N local cores or on a
SLURM cluster of K nodes, from per-unit costs fitted on benchmark files.

1. The jobs: Snakemake builds the config's DAG (`tacgen_lib.estimate.dag.dag_jobs`, `--forceall`).
2. Each job's seconds: `overhead + per_unit × units` of its cost class
   (`tacgen_lib.estimate.units.UNITS`, one line per rule), the line fitted by non-negative least
   squares (`tacgen_lib.estimate.calibration.fit_costs`) on the last run's benchmark files when
   they are a complete run of `--benchmarks-config`, else on the shipped calibration
   (`config/cost_calibration/`), labelled with the CPU it was measured on.
3. The run's wall: list scheduling of those jobs over the cores, honouring threads and
   dependencies (`tacgen_lib.estimate.schedule`), plus the workflow's own overhead (DAG building
   and per-job bookkeeping, fitted on the calibration runs' total wall times).

The command that prints an estimate is `tacgen_lib.estimate.command` (`python -m
tacgen_lib.estimate`). The per-unit costs hold for the calibration's CPU (the shipped one: the
2-core class without AVX-512, on which the budgets hold); on another CPU class scale them
(`--speed-factor`: a CPU with AVX-512 runs the same code about twice as fast).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import nnls

from tacgen_lib.estimate.calibration import (
    SHIPPED,
    Calibration,
    CostLine,
    MissingCalibrationError,
    fit_costs,
    last_run,
    load_calibration,
    run_calibration,
)
from tacgen_lib.estimate.dag import DagJob
from tacgen_lib.estimate.flops import flop_seconds
from tacgen_lib.estimate.schedule import (
    Machine,
    Task,
    critical_chain,
    list_schedule,
    longest_first_makespan,
)
from tacgen_lib.estimate.units import UNITS, job_units
from tacgen_lib.runtime.benchmarks import cpu_label

__all__ = [
    "Estimate",
    "RULE_COLUMNS",
    "job_seconds",
    "job_prediction",
    "workflow_overhead",
    "estimate_run",
    "choose_calibration",
]

RULE_COLUMNS = [
    "rule",
    "jobs",
    "threads",
    "unit",
    "units",
    "job_seconds",
    "start_s",
    "end_s",
    "per_unit_fitted",
]


@dataclass(frozen=True)
class Estimate:
    """A predicted run: `per_rule` (RULE_COLUMNS: jobs, summed job seconds (each job's wall: a
    job whose cells run on several threads counts its wall once), and the rule's span in the
    schedule, first start to last end), `critical` ((rule, seconds) of each job of the DAG's
    longest dependent chain), `makespan` (scheduled jobs), `overhead` (the
    workflow's own), `total` = makespan + overhead, `machine`, and `source` (which calibration
    and CPU)."""

    per_rule: pd.DataFrame
    makespan: float
    overhead: float
    machine: str
    source: str
    critical: tuple[tuple[str, float], ...] = ()

    @property
    def critical_seconds(self) -> float:
        """Length of the DAG's longest chain of dependent jobs (no core count shortens it)."""
        return sum(s for _, s in self.critical)

    @property
    def total(self) -> float:
        return self.makespan + self.overhead


def job_prediction(
    rule: str,
    config: Mapping[str, Any],
    wildcards: Mapping[str, str],
    threads: int,
    lines: dict[str, CostLine],
    *,
    gpu_tflops: float | None = None,
) -> tuple[str, float, float, bool]:
    """(cost class, units, predicted seconds, per-unit cost identified) of one job of `rule`.

    Seconds = its class's `overhead + per_unit × units` plus its FLOPs at the CPU's rate for
    its threads (`flops.flop_seconds`); for a rule whose job runs cells in one-thread workers
    (`UnitRule.cells`), the overhead plus the longest-first schedule of its cells' seconds on
    its threads. With `gpu_tflops`, the FLOPs of a rule whose model runs in torch
    (`UnitRule.on_gpu`) are charged at that effective rate instead (its per-unit cost, the
    data handling around the model, stays the CPU's). A class without calibration points
    raises naming it."""
    cost_class, units, flops = job_units(rule, config, wildcards)
    if cost_class not in lines:
        have = sorted(c for c in lines if c.split(":")[0] == rule)
        raise MissingCalibrationError(
            f"rule {rule!r}: cost class {cost_class!r} has no calibration point "
            f"(calibrated classes of this rule: {have or 'none'}); run a config that has such "
            "jobs and regenerate the calibration (python -m tacgen_lib.estimate.calibration)"
        )
    line, spec = lines[cost_class], UNITS[rule]
    gpu = gpu_tflops is not None and spec.on_gpu

    def arithmetic(f: float, t: int) -> float:
        return f / (gpu_tflops * 1e12) if gpu else flop_seconds(f, t)

    if spec.cells is not None:
        cells = [line.per_unit * u + arithmetic(f, 1) for u, f in spec.cells(config, wildcards)]
        seconds = line.overhead + longest_first_makespan(cells, threads)
    else:
        seconds = line.seconds(units) + arithmetic(flops, threads)
    return cost_class, units, seconds, line.identified


def job_seconds(
    jobs: Sequence[DagJob],
    config: dict[str, Any],
    lines: dict[str, CostLine],
    *,
    gpu_tflops: float | None = None,
) -> pd.DataFrame:
    """One row per job that runs: jobid, rule, cost class, units, predicted seconds
    (`job_prediction`), and whether its class's per-unit cost was identified (else a lower
    bound). A rule without a `UNITS` line, or a cost class without calibration points, raises
    naming it."""
    rows = []
    for job in jobs:
        if not job.runs:
            continue
        cost_class, units, seconds, identified = job_prediction(
            job.rule,
            job.config_of(config),
            job.wildcards,
            job.threads,
            lines,
            gpu_tflops=gpu_tflops,
        )
        rows.append((job.jobid, job.rule, cost_class, units, seconds, identified))
    columns = ["jobid", "rule", "cost_class", "units", "seconds", "identified"]
    return pd.DataFrame(rows, columns=columns)


def workflow_overhead(runs: pd.DataFrame) -> tuple[float, float]:
    """(startup seconds, seconds per job): the workflow's own time, fitted (non-negative least
    squares) on the calibration runs' total wall minus their scheduled measured job times,
    divided by each run's load factor (unshared seconds, as the job lines)."""
    if runs.empty:
        return 0.0, 0.0
    load = runs["load"].to_numpy(float) if "load" in runs else np.ones(len(runs))
    gap = runs["wall"].to_numpy(float) - runs["makespan"].to_numpy(float)
    gap = np.maximum(gap / load, 0.0)
    design = np.column_stack([np.ones(len(runs)), runs["jobs"].to_numpy(float)])
    (a, b), _ = nnls(design, gap)
    return float(a), float(b)


def estimate_run(
    jobs: Sequence[DagJob],
    config: dict[str, Any],
    calibration: Calibration,
    machine: Machine,
    *,
    machine_label: str = "",
    speed: float = 1.0,
    gpu_tflops: float | None = None,
) -> Estimate:
    """Predict the run of `jobs` (a DAG from `dag_jobs`) on `machine` from `calibration`.

    `config`: the run's validated config, the schema's defaults filled in (`dag_jobs` returns
    the one the workflow validated in rules/common.smk; a job of a cost setting counts its
    own, `DagJob.config_of`), whose settings the unit lines read (`estimate.counts`).

    The calibration's lines give seconds on idle cores (`calibration.unshared_seconds`);
    `speed` multiplies every second (jobs and workflow overhead) into this machine's wall: its
    load factor (1 on idle cores; `calibration.load_factors`) times its CPU's slowness against
    the calibration's (~0.5 on a CPU with AVX-512 against the shipped calibration's, which
    was measured on the 2-core class without it)."""
    if not speed > 0:
        raise ValueError(f"speed factor must be > 0, got {speed}")
    lines = fit_costs(calibration.points)
    per_job = job_seconds(jobs, config, lines, gpu_tflops=gpu_tflops)
    per_job["seconds"] *= speed
    seconds = dict(zip(per_job["jobid"], per_job["seconds"], strict=True))
    tasks = [Task(j.jobid, seconds.get(j.jobid, 0.0), j.threads, j.deps, j.local) for j in jobs]
    schedule = list_schedule(tasks, machine)
    per_job["start"] = per_job["jobid"].map(schedule.start)
    per_job["end"] = per_job["jobid"].map(schedule.end)
    threads = {j.jobid: j.threads for j in jobs}
    per_job["threads"] = per_job["jobid"].map(threads)
    per_rule = (
        per_job.groupby("rule", sort=False)
        .agg(
            jobs=("jobid", "size"),
            threads=("threads", "max"),
            units=("units", "sum"),
            job_seconds=("seconds", "sum"),
            start_s=("start", "min"),
            end_s=("end", "max"),
            per_unit_fitted=("identified", "all"),
        )
        .reset_index()
        .sort_values(["start_s", "rule"])
    )
    per_rule["unit"] = per_rule["rule"].map(lambda r: UNITS[r].unit)
    startup, per_job_s = workflow_overhead(calibration.runs)
    overhead = (startup + per_job_s * len(per_job)) * speed
    rule_of = {j.jobid: j.rule for j in jobs}
    _, chain = critical_chain(tasks)
    return Estimate(
        per_rule=per_rule[RULE_COLUMNS].reset_index(drop=True),
        makespan=schedule.makespan,
        overhead=overhead,
        machine=machine_label,
        source=calibration.source,
        critical=tuple((rule_of[k], seconds.get(k, 0.0)) for k in chain if k in seconds),
    )


def choose_calibration(
    *,
    calibration: str | os.PathLike[str] | None,
    benchmarks: str | os.PathLike[str],
    benchmarks_config: str | os.PathLike[str] | None = None,
    workdir: str | os.PathLike[str] = ".",
) -> Calibration:
    """The last run's benchmark files when `benchmarks` holds a complete run of
    `benchmarks_config` (default: the config of the newest finished Snakemake run of
    `workdir`, from its log; the embedded default if none is named there), its cost classes
    with the shipped ones filling any class it lacks (the shipped runs' totals give the
    workflow overhead); else the shipped calibration (or the folder `calibration`, which always
    wins). The returned `source` says which, and why."""
    shipped = load_calibration(calibration or SHIPPED)
    if calibration is not None:
        return shipped
    bench = Path(workdir) / benchmarks
    if not bench.is_dir():
        return Calibration(shipped.points, shipped.runs, f"{shipped.source} (no {benchmarks} here)")
    if benchmarks_config is None:
        log = last_run(workdir)
        benchmarks_config = (
            log.configfiles[0] if log is not None and log.configfiles else "config/config.yaml"
        )
    try:
        last, _ = run_calibration(benchmarks_config, bench, run="last run", workdir=workdir)
    except ValueError as exc:
        return Calibration(
            shipped.points, shipped.runs, f"{shipped.source} ({benchmarks} not used: {exc})"
        )
    fill = shipped.points[~shipped.points["cost_class"].isin(set(last["cost_class"]))]
    points = pd.concat([last, fill], ignore_index=True)
    source = (
        f"last run: {benchmarks} as a run of {benchmarks_config} ({len(last)} jobs; CPU {cpu_label()})"
        + (
            f", {fill['cost_class'].nunique()} classes from the shipped calibration"
            if len(fill)
            else ""
        )
        + f"; workflow overhead from {shipped.source}"
    )
    return Calibration(points, shipped.runs, source)
