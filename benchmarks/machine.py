"""What every benchmark shares: one line naming the machine it ran on (its figures depend on
the CPU's vector units: the same code measured 0.41 and 0.65 of the GEMM roofline on two 2-core
machines), best-of timing by wall and CPU clock, and the GEMM rate a roofline is measured
against."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import NamedTuple

from tacgen_lib.runtime.benchmarks import cpu_label


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
