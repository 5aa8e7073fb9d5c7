"""What every benchmark shares: one line naming the machine it ran on (its figures depend on
the CPU's vector units: the same code reaches another fraction of the GEMM roofline on another
CPU class), best-of timing by wall and CPU clock, the GEMM rate a roofline is measured against,
the tiny mode and the config of the finished run a benchmark reads.

Run as a script, it prints the machine's speed at that moment, to quote beside any whole-run
timing (a cold run, `make test`): the CPU (model, family, cores, widest vector extension), the
load average, a one-thread float32 GEMM rate, and the seconds a fresh interpreter takes to
import the libraries every job imports (the preloaded interpreter's list,
`tacgen_lib.runtime.preload_server.PRELOADED_MODULES`): what a short job costs, as the
machine is loaded now. Best of `--repeats`.

    .venv/bin/python benchmarks/machine.py [--repeats 3]

The tiny mode (`TINY_ENV`, ``TACGEN_BENCH_TINY=1``): every script runs its whole path at the
smallest sizes, in seconds, and prints its figures, which then measure nothing but that the
path still runs (`make test` runs every script so, tests/test_benchmarks.py). A script states
its tiny sizes once, as the defaults `parse_args` gives its arguments in that mode (an
argument given on the command line still wins), and `sized` for a size it takes no argument
for. A script that reads a finished run reads one of config/test.yaml in the tiny mode.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

from tacgen_lib.runtime.benchmarks import cpu_label, cpuinfo

ROOT = Path(__file__).resolve().parents[1]
#: the environment variable that runs a benchmark in its tiny mode (anything but "" or "0")
TINY_ENV = "TACGEN_BENCH_TINY"
#: the config a tiny mode's finished run was made with (merged over config/config.yaml)
TINY_CONFIG = "config/test.yaml"
T = TypeVar("T")


def tiny() -> bool:
    """Whether this process runs in the tiny mode (`TINY_ENV`)."""
    return os.environ.get(TINY_ENV, "0") not in ("", "0")


def sized(real: T, small: T) -> T:
    """`real`, or `small` in the tiny mode: a size the script takes no argument for."""
    return small if tiny() else real


def parse_args(
    parser: argparse.ArgumentParser,
    tiny_defaults: Mapping[str, Any],
    argv: list[str] | None = None,
) -> argparse.Namespace:
    """`parser`'s arguments; in the tiny mode with `tiny_defaults` (argument dest -> value) for
    its defaults, and a line saying so. A dest the parser lacks is an error in either mode, so
    a renamed argument cannot leave a tiny size behind."""
    dests = {action.dest for action in parser._actions}
    unknown = sorted(set(tiny_defaults) - dests)
    if unknown:
        raise ValueError(f"tiny defaults {unknown} name no argument of {parser.prog}")
    if tiny():
        parser.set_defaults(**tiny_defaults)
        print(f"tiny mode ({TINY_ENV}): the smallest sizes; the figures only show the path runs")
    return parser.parse_args(argv)


def run_config(configfile: str | os.PathLike[str]) -> dict:
    """The validated config of a finished run made with `--configfile configfile`: the file
    merged over config/config.yaml as Snakemake merges it (config/config.yaml itself: the
    default), the schema's defaults filled in."""
    from tacgen_lib.estimate.command import merged_config
    from tacgen_lib.workflow_config import validate_config

    config = merged_config([Path(configfile).absolute()], ROOT)
    config["scenes_file"] = str(ROOT / config["scenes_file"])
    return validate_config(config, ROOT / "config/config.schema.yaml")


class Timing(NamedTuple):
    """Seconds by the wall clock and by process CPU time (all threads)."""

    wall: float
    cpu: float

    def min(self, other: Timing) -> Timing:
        return Timing(min(self.wall, other.wall), min(self.cpu, other.cpu))


def best_of(fn: Callable[[], object], reps: int) -> Timing:
    """Best wall and best process-CPU seconds of `reps` calls of `fn` (after one warm-up)."""
    fn()
    wall, cpu = float("inf"), float("inf")
    for _ in range(reps):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - w0)
        cpu = min(cpu, time.process_time() - c0)
    return Timing(wall, cpu)


def gemm_peak(n: int = 1024, reps: int = 5) -> Timing:
    """Seconds of one n x n x n float32 torch.matmul (best of `reps`): the roofline's rate."""
    import torch  # only the benchmarks that need a roofline pay for importing torch

    a, b = torch.randn(n, n), torch.randn(n, n)
    return best_of(lambda: a @ b, reps)


def describe() -> str:
    """CPU model, cores, widest x86 vector extension and the 1-minute load average."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{cpu_label()}, load average {load:.2f}"


def cpu_family() -> str:
    """``family F model M`` of the first CPU in /proc/cpuinfo: the 2-core AMD EPYC classes differ
    in family and model (family 25 holds Zen 3, without AVX-512, and Zen 4, model 17, with it;
    family 26 has it), so a timing quotes both beside the vector extension `describe` gives."""
    info = cpuinfo()
    return f"family {info.get('cpu family', '?')} model {info.get('model', '?')}"


def import_seconds(repeats: int) -> Timing:
    """Best wall and CPU seconds of a fresh interpreter importing what every job imports
    (`PRELOADED_MODULES`), measured by the child itself around its imports."""
    from tacgen_lib.runtime.preload_server import PRELOADED_MODULES

    code = (
        "import importlib, os, time\n"
        "os.environ.setdefault('MUJOCO_GL', 'egl')\n"
        "w, c = time.perf_counter(), time.process_time()\n"
        f"for m in {list(PRELOADED_MODULES)!r}: importlib.import_module(m)\n"
        "print(time.perf_counter() - w, time.process_time() - c)\n"
    )
    best = Timing(float("inf"), float("inf"))
    for _ in range(repeats):
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        ).stdout.split()
        best = best.min(Timing(float(out[0]), float(out[1])))
    return best


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[1])
    parser.add_argument("--repeats", type=int, default=3)
    args = parse_args(parser, {"repeats": 1}, argv)
    import torch

    torch.set_num_threads(1)
    n = 1024
    gemm = gemm_peak(n, args.repeats)
    imports = import_seconds(args.repeats)
    print(f"machine: {describe()}, {cpu_family()}")
    print(f"GEMM {n}^3 float32, one thread: {2 * n**3 / gemm.wall / 1e9:.1f} GFLOP/s")
    print(
        f"a fresh interpreter importing the jobs' libraries: {imports.wall:.2f} s wall, "
        f"{imports.cpu:.2f} s CPU (best of {args.repeats})"
    )


if __name__ == "__main__":
    main()
