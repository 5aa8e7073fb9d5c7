"""How close the run-time estimate comes to a finished cold run (`tacgen_lib.estimate`).

Reads a finished run of a config (its Snakemake log for the wall, its `benchmark:` files for
each job's seconds) and estimates the same DAG from the shipped calibration only (earlier runs,
never this one). One number comes from the run: its speed against the calibration, the median
over its jobs of measured / predicted seconds, which folds together what no fixed calibration
can know (this machine's load and CPU class). What is compared is everything else: which jobs
the DAG holds, their relative costs, their schedule on the cores and the workflow's overhead.
Prints the predicted and measured wall and their ratio (the estimate aims at 0.75-1.25).

    .venv/bin/python benchmarks/bench_estimate.py                 # runs config/test.yaml cold
    .venv/bin/python benchmarks/bench_estimate.py --run DIR [--configfile config/config.yaml]
        [TARGET ...]

Without ``--run`` it copies the repository's workflow files into a temporary folder and runs
`snakemake --cores N --configfile config/test.yaml` there first. Targets (default the
workflow's `all`) make the run, and the DAG estimated, stop at them: the tiny mode runs cold
one corpus of config/test.yaml to its merged samples (`TINY_TARGETS`). Not a
test: the ratio depends on what else the machine does while the run goes (a job takes longer
than its idle CPU time beside other jobs, and much longer beside a dozen), which a unit test
cannot control.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

import machine
import numpy as np
from machine import TINY_CONFIG, parse_args

from tacgen_lib.estimate.calibration import fit_costs, last_run, load_calibration
from tacgen_lib.estimate.dag import dag_jobs
from tacgen_lib.estimate.predict import estimate_run, job_seconds
from tacgen_lib.estimate.schedule import local_machine
from tacgen_lib.runtime.benchmarks import read_benchmark

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from snakemake_run import SNAKEMAKE, copy_tree  # noqa: E402  (the tests' workflow copy)

#: the tiny mode's targets: one corpus of config/test.yaml simulated and merged (two jobs)
TINY_TARGETS = ["results/corpus/sim_controlled/samples.parquet"]


def cold_run(
    dest: Path,
    configfile: str,
    cores: int,
    env: dict[str, str] | None = None,
    targets: Sequence[str] = (),
) -> Path:
    """Copy the workflow into `dest` and run `configfile` there cold (in environment `env`,
    default this process's), to `targets` (default the workflow's `all`); returns `dest`."""
    copy_tree(dest)
    # quiet about the rules only: the log must keep its progress lines, which `last_run` reads
    cmd = [*SNAKEMAKE, *targets, "--cores", str(cores), "--configfile", configfile]
    cmd += ["--quiet", "rules"]
    print(f"running snakemake {' '.join(cmd[3:])} in {dest}", flush=True)
    subprocess.run(cmd, cwd=dest, env=env, check=True)
    return dest


def compare(run: Path, configfile: str, cores: int, targets: Sequence[str] = ()) -> float:
    """Print the estimate of `run`'s DAG (to `targets`, default `all`) against its measured
    wall; returns their ratio."""
    log = last_run(run)
    if log is None:
        raise SystemExit(f"{run}: no finished Snakemake run (no log saying '(100%) done')")
    jobs, config = dag_jobs([configfile], workdir=run, cores=cores, targets=list(targets) or None)
    cal = load_calibration()
    predicted = job_seconds(jobs, config, fit_costs(cal.points)).set_index("jobid")["seconds"]
    ratios = [
        read_benchmark(run / j.benchmark).wall / predicted[j.jobid]
        for j in jobs
        if j.runs and j.benchmark and predicted.get(j.jobid, 0) > 0 and (run / j.benchmark).exists()
    ]
    if not ratios:
        raise SystemExit(f"{run}: no benchmark files of the DAG's jobs")
    speed = float(np.median(ratios))
    est = estimate_run(jobs, config, cal, local_machine(cores), speed=speed)
    ratio = est.total / log.wall
    print(
        f"{configfile}: {len(ratios)} jobs with benchmark files; this run's speed "
        f"x{speed:.2f} of the calibration ({est.source})"
    )
    print(
        f"predicted {est.total:.0f} s, measured {log.wall:.0f} s: ratio {ratio:.2f} "
        f"({'within' if 0.75 <= ratio <= 1.25 else 'OUTSIDE'} 0.75-1.25)"
    )
    return ratio


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, help="a finished run's directory (default: run one)")
    ap.add_argument("--configfile", default="config/test.yaml")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("targets", nargs="*", help="Snakemake targets (default: all)")
    args = parse_args(ap, {"configfile": TINY_CONFIG, "targets": TINY_TARGETS})
    print(machine.describe(), flush=True)
    run_args = (args.configfile, args.cores)
    if args.run is not None:
        compare(args.run, *run_args, args.targets)
        return
    with tempfile.TemporaryDirectory(prefix="bench_estimate_") as tmp:
        compare(cold_run(Path(tmp), *run_args, targets=args.targets), *run_args, args.targets)


if __name__ == "__main__":
    main()
