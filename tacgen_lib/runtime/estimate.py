"""Estimate before running: per-rule and total wall time of a config's DAG on N local cores or
on a SLURM cluster of K nodes, from per-unit costs fitted on benchmark files.

1. The jobs: Snakemake builds the config's DAG (`tacgen_lib.runtime.dag.dag_jobs`, `--forceall`).
2. Each job's seconds: `overhead + per_unit × units` of its cost class
   (`tacgen_lib.runtime.units.UNITS`, one line per rule), the line fitted by non-negative least
   squares (`tacgen_lib.runtime.calibration.fit_costs`) on the last run's benchmark files when
   they are a complete run of `--benchmarks-config`, else on the shipped calibration
   (`config/cost_calibration/`), labelled with the CPU it was measured on.
3. The run's wall: list scheduling of those jobs over the cores, honouring threads and
   dependencies (`tacgen_lib.runtime.schedule`), plus the workflow's own overhead (DAG building
   and per-job bookkeeping, fitted on the calibration runs' total wall times).

    .venv/bin/python -m tacgen_lib.runtime.estimate --configfile config/paper.yaml --cores 2
    .venv/bin/python -m tacgen_lib.runtime.estimate --configfile config/paper.yaml \\
        --slurm-nodes 8 --cores-per-node 32

The per-unit costs hold for the calibration's CPU (the shipped one: the 2-core class without
AVX-512, on which the budgets hold); on another CPU class scale them (`--speed-factor`: a CPU
with AVX-512 runs the same code about twice as fast).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import nnls

from tacgen_lib.runtime.benchmarks import cpu_label
from tacgen_lib.runtime.calibration import (
    SHIPPED,
    Calibration,
    CostLine,
    MissingCalibrationError,
    fit_costs,
    last_run,
    load_calibration,
    run_calibration,
)
from tacgen_lib.runtime.dag import DagJob, dag_jobs
from tacgen_lib.runtime.schedule import (
    Machine,
    Task,
    critical_chain,
    list_schedule,
    local_machine,
    longest_first_makespan,
    slurm_machine,
)
from tacgen_lib.runtime.units import UNITS, MissingUnitsError, flop_seconds, job_units

__all__ = [
    "Estimate",
    "RULE_COLUMNS",
    "job_seconds",
    "job_prediction",
    "workflow_overhead",
    "estimate_run",
    "choose_calibration",
    "main",
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
    its threads (`units.flop_seconds`); for a rule whose job runs cells in one-thread workers
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
            "jobs and regenerate the calibration (python -m tacgen_lib.runtime.calibration)"
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


def _profile(profile: str | os.PathLike[str]) -> dict[str, Any]:
    path = Path(profile) / "config.yaml"
    if not str(profile) or not path.is_file():
        return {}
    import yaml

    return yaml.safe_load(path.read_text()) or {}


def profile_threads(profile: str | os.PathLike[str]) -> dict[str, int]:
    """`set-threads:` of a Snakemake profile folder (its config.yaml); {} without one."""
    data = _profile(profile)
    return {str(k): int(v) for k, v in (data.get("set-threads") or {}).items()}


def profile_jobs(profile: str | os.PathLike[str], default: int = 50) -> int:
    """`jobs:` of a Snakemake profile folder (jobs queued or running at once); `default`
    without one."""
    return int(_profile(profile).get("jobs", default))


def merged_config(
    configfiles: Sequence[str | os.PathLike[str]], workdir: str | os.PathLike[str] = "."
) -> dict[str, Any]:
    """config/config.yaml with `configfiles` merged over it as Snakemake's `--configfile`
    does (recursively, key by key), before the workflow's own additions and validation."""
    import yaml
    from snakemake.utils import update_config

    config = yaml.safe_load((Path(workdir) / "config" / "config.yaml").read_text()) or {}
    for f in configfiles:
        path = Path(f) if Path(f).is_absolute() else Path(workdir) / f
        update_config(config, yaml.safe_load(path.read_text()) or {})
    return config


def missing_checkpoints(
    config: Mapping[str, Any], workdir: str | os.PathLike[str] = "."
) -> dict[str, str]:
    """Config key of every backbone (main features, families run) whose checkpoint file is not
    here (the run would stop on it: `families.check_checkpoint_file`) -> its checkpoint."""
    from tacgen_lib.features.families import BackboneSpec, check_checkpoint_file
    from tacgen_lib.io.config import ConfigError

    specs = {f"features.backbones.{m}": s for m, s in config["features"]["backbones"].items()}
    families = (config.get("backbones") or {}).get("families") or {}
    for name in (config.get("backbones") or {}).get("run") or ():
        for m, spec in (families.get(name) or {}).items():
            specs[f"backbones.families.{name}.{m}"] = spec
    missing = {}
    for key, spec in specs.items():
        try:
            check_checkpoint_file(BackboneSpec.from_config(spec), where=key, root=workdir)
        except ConfigError:
            missing[key] = str(spec["checkpoint"])
    return missing


def stand_in_checkpoints(
    missing: Mapping[str, str], config: Mapping[str, Any], folder: str | os.PathLike[str]
) -> Path:
    """A config file in `folder` pointing each missing checkpoint key at an empty file of the
    same name there: the DAG a run would have once the files are downloaded (building it reads
    no checkpoint). For the estimate only; the run itself still stops on the missing file."""
    import yaml

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    override: dict[str, Any] = {}
    for key in missing:
        path = key.split(".")
        spec: Any = config
        for k in path:
            spec = spec[k]
        stand_in = folder / Path(spec["checkpoint"]).name
        stand_in.touch()
        node = override
        for k in path:
            node = node.setdefault(k, {})
        node["checkpoint"] = str(stand_in)
    out = folder / "stand_in_checkpoints.yaml"
    out.write_text(yaml.safe_dump(override))
    return out


def format_estimate(est: Estimate) -> str:
    """The per-rule table and the total, as printed by the command."""
    table = est.per_rule.copy()
    lines = [
        f"Run-time estimate on {est.machine}",
        f"calibration: {est.source}",
        "",
        f"{'rule':28s} {'jobs':>5s} {'thr':>3s} {'job-seconds':>12s} {'start':>8s} {'end':>8s}  unit",
    ]
    for r in table.itertuples():
        flag = "" if r.per_unit_fitted else " *"
        lines.append(
            f"{r.rule + flag:28s} {r.jobs:5d} {r.threads:3d} {r.job_seconds:12.1f} "
            f"{r.start_s:8.1f} {r.end_s:8.1f}  {r.unit}"
        )
    if not table["per_unit_fitted"].all():
        lines += [
            "* per-unit cost not identified (the calibration measured one size of these jobs, "
            "or sizes too close): flat at the measured mean, a lower bound for larger jobs"
        ]
    chain = " -> ".join(f"{rule} ({seconds:.0f} s)" for rule, seconds in est.critical)
    lines += [
        "",
        f"critical path (longest chain of dependent jobs, {est.critical_seconds:.0f} s = "
        f"{est.critical_seconds / 3600:.2f} h; no core count shortens it): {chain}",
        f"jobs: {int(table['jobs'].sum())}, job-seconds: {table['job_seconds'].sum():.0f} s",
        f"scheduled jobs (makespan): {est.makespan:.0f} s; workflow overhead: {est.overhead:.0f} s",
        f"total predicted wall time: {est.total:.0f} s ({est.total / 60:.1f} min, "
        f"{est.total / 3600:.2f} h)",
    ]
    return "\n".join(lines)


def write_table(est: Estimate, out: str | os.PathLike[str]) -> None:
    """The per-rule table with a `total` row (machine and source in columns) to `out`: .parquet,
    .csv or .tsv by suffix; written atomically (temp file + rename)."""
    out = Path(out)
    table = est.per_rule.copy()
    total = {
        "rule": "total",
        "jobs": int(table["jobs"].sum()),
        "threads": int(table["threads"].max()),
        "unit": "wall seconds incl. workflow overhead",
        "units": float("nan"),
        "job_seconds": float(table["job_seconds"].sum()),
        "start_s": 0.0,
        "end_s": est.total,
        "per_unit_fitted": bool(table["per_unit_fitted"].all()),
    }
    table = pd.concat([table, pd.DataFrame([total])], ignore_index=True)
    table["machine"] = est.machine
    table["source"] = est.source
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    if out.suffix == ".parquet":
        table.to_parquet(tmp, index=False)
    elif out.suffix in (".csv", ".tsv"):
        table.to_csv(tmp, index=False, sep="," if out.suffix == ".csv" else "\t")
    else:
        raise ValueError(f"--out {out}: use a .parquet, .csv or .tsv file")
    tmp.replace(out)


def main(argv: Sequence[str] | None = None) -> Estimate:
    parser = argparse.ArgumentParser(
        prog="python -m tacgen_lib.runtime.estimate",
        description="Predict per-rule and total wall time of a config's DAG before running it.",
    )
    parser.add_argument(
        "--configfile", action="append", default=[], help="config merged over the default"
    )
    parser.add_argument("--cores", type=int, default=2, help="local cores (default 2)")
    parser.add_argument("--slurm-nodes", type=int, default=None, help="SLURM nodes K")
    parser.add_argument("--cores-per-node", type=int, default=32, help="cores per SLURM node")
    parser.add_argument(
        "--queue-s", type=float, default=30.0, help="SLURM queue + start seconds per job"
    )
    parser.add_argument(
        "--max-jobs",
        type=int,
        default=None,
        help="SLURM jobs at once (default: the profile's `jobs:`)",
    )
    parser.add_argument(
        "--gpu-tflops",
        type=float,
        default=None,
        help="a GPU class: the FLOPs of the rules whose model runs in torch at this effective "
        "rate (TFLOP/s; an assumption until a GPU run calibrates it), their other costs the "
        "CPU's",
    )
    parser.add_argument(
        "--profile",
        default="profiles/slurm",
        help="SLURM profile whose `set-threads:` apply (default profiles/slurm; '' for none)",
    )
    parser.add_argument(
        "--calibration", default=None, help="a calibration folder (default: last run, else shipped)"
    )
    parser.add_argument("--benchmarks", default="results/benchmarks", help="the last run's folder")
    parser.add_argument(
        "--benchmarks-config",
        default=None,
        help="the config the last run used (default: read from its Snakemake log)",
    )
    parser.add_argument(
        "--load-factor",
        type=float,
        default=1.0,
        help="wall here over wall on idle cores (default 1: idle; 6-10 with a dozen other "
        "jobs sharing 2 cores)",
    )
    parser.add_argument(
        "--speed-factor",
        type=float,
        default=1.0,
        help="CPU seconds here per calibration CPU second (e.g. 0.5 on a CPU with AVX-512)",
    )
    parser.add_argument("--workdir", default=".", help="the workflow's directory")
    parser.add_argument("--out", default=None, help="write the per-rule table (.parquet/.csv/.tsv)")
    args = parser.parse_args(argv)

    if args.max_jobs is None:
        args.max_jobs = profile_jobs(Path(args.workdir) / args.profile)
    if args.slurm_nodes:
        machine = slurm_machine(
            args.slurm_nodes,
            args.cores_per_node,
            queue_s=args.queue_s,
            max_jobs=args.max_jobs,
            local_cores=args.cores,
        )
        label = (
            f"SLURM, {args.slurm_nodes} nodes x {args.cores_per_node} cores, {args.queue_s:g} s "
            f"queue per job, <= {args.max_jobs} jobs at once, localrules on {args.cores} cores, "
            f"threads of {args.profile or 'the rules'}"
        )
        cap = args.cores_per_node
    else:
        machine, label, cap = local_machine(args.cores), f"{args.cores} local cores", args.cores
    set_threads = profile_threads(Path(args.workdir) / args.profile) if args.slurm_nodes else {}
    # official checkpoints not downloaded yet: priced as if they were (a run stops on them)
    merged = merged_config(args.configfile, args.workdir)
    missing = missing_checkpoints(merged, args.workdir)
    with tempfile.TemporaryDirectory(prefix="tacgen-estimate-") as tmp:
        extra = [str(stand_in_checkpoints(missing, merged, tmp))] if missing else []
        jobs, config = dag_jobs(
            [*args.configfile, *extra], workdir=args.workdir, cores=cap, set_threads=set_threads
        )
    calibration = choose_calibration(
        calibration=args.calibration,
        benchmarks=args.benchmarks,
        benchmarks_config=args.benchmarks_config,
        workdir=args.workdir,
    )
    configs = " + ".join(["config/config.yaml", *args.configfile])
    if args.load_factor != 1.0:
        label += f", load factor {args.load_factor:g}"
    if args.speed_factor != 1.0:
        label += f", x{args.speed_factor:g} the calibration CPU's seconds"
    if args.gpu_tflops is not None:
        label += (
            f", a GPU per job whose model runs in torch at an assumed {args.gpu_tflops:g} "
            "TFLOP/s effective (not calibrated)"
        )
    try:
        est = estimate_run(
            jobs,
            config,
            calibration,
            machine,
            machine_label=f"{label} ({configs})",
            speed=args.speed_factor * args.load_factor,
            gpu_tflops=args.gpu_tflops,
        )
    except (MissingCalibrationError, MissingUnitsError) as exc:
        # what to run is in the message; a traceback would only hide it
        raise SystemExit(f"estimate: {exc}") from None
    print(format_estimate(est))
    if missing:
        from tacgen_lib.features.families import OFFICIAL_CHECKPOINTS

        print(
            f"\nnote: {len(missing)} checkpoint keys name files that are not here; priced as if "
            "they were, but a run stops at parse time until they are downloaded:"
        )
        for key, path in missing.items():
            where = OFFICIAL_CHECKPOINTS.get(Path(path).name, "no official release of that name")
            print(f"  {key}.checkpoint: {path} ({where})")
    if args.out:
        write_table(est, args.out)
        print(f"per-rule table: {args.out}", file=sys.stderr)
    return est


if __name__ == "__main__":
    main()
