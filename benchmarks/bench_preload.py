"""What the preloaded interpreter saves (`tacgen_lib.runtime.preload`): one config run cold
twice in fresh copies of the workflow, each job in its own interpreter (`TACGEN_PRELOAD=0`)
and forked from the server, on idle cores. Prints machine, per run its wall time, the sum and
median of its jobs' benchmark seconds and how many jobs the server ran, the ratios, and
whether every edge is the same bit for bit.

    .venv/bin/python benchmarks/bench_preload.py [--configfile config/test.yaml] [--cores 2]
        [TARGET ...]

Not a test: two cold runs take minutes, and the ratio moves with the machine's load. The
targets (default the workflow's `all`) let a run stop early: the tiny mode runs one corpus of
config/test.yaml to its merged samples (bench_estimate.TINY_TARGETS), too few jobs for the
server to start (`tacgen_lib.runtime.preload_server.MIN_JOBS`): both runs are fresh then.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import machine
from bench_estimate import TINY_TARGETS, cold_run
from machine import TINY_CONFIG, parse_args

from tacgen_lib.runtime.benchmarks import read_benchmark
from tacgen_lib.runtime.preload import SWITCH_ENV, usage_path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from snakemake_run import edge_hashes  # noqa: E402  (the tests' edge hashes)


def timed_run(dest: Path, configfile: str, cores: int, preload: bool, targets: list[str]) -> dict:
    """`configfile` cold in a copy of the workflow at `dest` (bench_estimate.cold_run) to
    `targets`, with or without the server; its wall, job seconds, jobs served and edge hashes."""
    env = {**os.environ, SWITCH_ENV: "1" if preload else "0"}
    label = "preloaded" if preload else "fresh"
    t0 = time.monotonic()
    cold_run(dest, configfile, cores, env, targets)
    wall = time.monotonic() - t0
    benches = sorted((dest / "results" / "benchmarks").rglob("*.tsv"))
    seconds = [read_benchmark(b).wall for b in benches]
    served = sum(usage_path(b).exists() for b in benches)
    return {
        "label": label,
        "wall": wall,
        "jobs": len(seconds),
        "sum": sum(seconds),
        "median": statistics.median(seconds),
        "served": served,
        "edges": edge_hashes(dest),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configfile", default="config/test.yaml")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("targets", nargs="*", help="Snakemake targets (default: all)")
    args = parse_args(ap, {"configfile": TINY_CONFIG, "targets": TINY_TARGETS})
    print(f"machine: {machine.describe()}")
    with tempfile.TemporaryDirectory(prefix="tacgen-bench-preload-") as tmp:
        runs = [
            timed_run(Path(tmp) / name, args.configfile, args.cores, preload, args.targets)
            for name, preload in (("fresh", False), ("preloaded", True))
        ]
    print(f"{'run':<10} {'wall s':>8} {'jobs':>5} {'job s sum':>10} {'median':>7} {'served':>7}")
    for r in runs:
        print(
            f"{r['label']:<10} {r['wall']:8.1f} {r['jobs']:5d} {r['sum']:10.1f} "
            f"{r['median']:7.2f} {r['served']:7d}"
        )
    fresh, pre = runs
    print(
        f"preloaded / fresh: wall {pre['wall'] / fresh['wall']:.2f}, job seconds "
        f"{pre['sum'] / fresh['sum']:.2f}, median job {pre['median'] / fresh['median']:.2f}"
    )
    same = fresh["edges"] == pre["edges"]
    differ = sorted(k for k in fresh["edges"] if pre["edges"].get(k) != fresh["edges"][k])
    print(f"edges: {len(fresh['edges'])}, bit-identical: {same}" + ("" if same else f" {differ}"))


if __name__ == "__main__":
    main()
