"""A job's independent cells on its cores: forked single-threaded workers.

The regime's jobs (regime_generators, regime_evaluate) are loops over cells that share
nothing but their inputs: one generator per (pool size, pairing), every arm of one
(target, N_L). Their work is hundreds of small solves, interpreter-bound, which extra BLAS or
torch threads do not speed up; so a job that Snakemake gives 2 threads runs its cells in 2
forked processes of one thread each (`fork_map`). A cell computes in a worker exactly what it
computes in the job's own process (the same code on the same inputs with one BLAS and one
torch thread), so the results do not depend on the number of workers: tested bit for bit.

Workers are forked (they inherit the job's inputs and imports; nothing is pickled but the
cell's index and its result), die with the job (``PR_SET_PDEATHSIG``), and a worker that dies
fails the job (``BrokenProcessPool``) rather than hanging it. Their CPU time is the job's: the
preloaded interpreter's ``wait4`` counts reaped descendants.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import signal
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

__all__ = ["fork_map"]

T = TypeVar("T")
R = TypeVar("R")

# the map a forked worker runs: set in the parent just before the fork, read by the workers
_TASK: tuple[Callable[[Any], Any], Sequence[Any]] | None = None


def _worker_start() -> None:
    """One thread per worker, and the worker ends if the job's process does."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the executor still reaps its workers
        pass
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    torch = sys.modules.get("torch")  # only where the job imported it (never imported here)
    if torch is not None:
        torch.set_num_threads(1)


def _run(i: int) -> Any:
    assert _TASK is not None
    fn, items = _TASK
    return fn(items[i])


def fork_map(
    fn: Callable[[T], R],
    items: Sequence[T],
    workers: int,
    *,
    cost: Callable[[T], float] | None = None,
) -> list[R]:
    """``[fn(x) for x in items]``, computed by `workers` forked single-threaded processes.

    workers <= 1 (or a single item) runs the loop here, in this process. ``cost`` (an
    estimate of each item's run time) hands the costliest items out first, which balances
    the workers (longest processing time first); the results keep the order of `items`.
    An exception raised by `fn` in a worker is raised here.
    """
    global _TASK
    items = list(items)
    if workers <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    order = list(range(len(items)))
    if cost is not None:
        order.sort(key=lambda i: -cost(items[i]))
    _TASK = (fn, items)
    try:
        with ProcessPoolExecutor(
            max_workers=min(workers, len(items)),
            mp_context=multiprocessing.get_context("fork"),
            initializer=_worker_start,
        ) as pool:
            futures = {i: pool.submit(_run, i) for i in order}
            return [futures[i].result() for i in range(len(items))]
    finally:
        _TASK = None
