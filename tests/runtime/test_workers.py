"""`runtime.workers.fork_map`: a job's cells in forked single-threaded workers."""

from __future__ import annotations

import os
import signal
from concurrent.futures.process import BrokenProcessPool

import numpy as np
import pytest

from tacgen_lib.runtime.workers import fork_map


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def test_results_keep_the_order_of_the_items_whatever_the_cost_order():
    items = list(range(7))
    out = fork_map(_square_and_pid, items, 2, cost=lambda x: x % 3)
    assert [r for r, _ in out] == [x * x for x in items]
    assert os.getpid() not in {pid for _, pid in out}  # computed by the workers


def test_one_worker_or_one_item_runs_in_this_process():
    assert {pid for _, pid in fork_map(_square_and_pid, [1, 2, 3], 1)} == {os.getpid()}
    assert fork_map(_square_and_pid, [4], 2) == [(16, os.getpid())]
    assert fork_map(_square_and_pid, [], 2) == []


def test_a_closure_over_unpicklable_state_runs_in_the_workers():
    """Workers are forked: the function and its inputs are inherited, never pickled."""
    big = {"rows": np.arange(10.0)}
    out = fork_map(lambda i: float(big["rows"][i] * 2), [1, 3], 2)
    assert out == [2.0, 6.0]


def test_an_exception_in_a_worker_is_raised_here():
    def fail_on_two(x: int) -> int:
        if x == 2:
            raise ValueError(f"cell {x} failed")
        return x

    with pytest.raises(ValueError, match="cell 2 failed"):
        fork_map(fail_on_two, [1, 2, 3], 2)


def test_a_worker_that_dies_fails_the_map_instead_of_hanging_it():
    def die_on_one(x: int) -> int:
        if x == 1:
            os.kill(os.getpid(), signal.SIGKILL)
        return x

    with pytest.raises(BrokenProcessPool):
        fork_map(die_on_one, [0, 1, 2], 2)


def test_workers_compute_with_one_blas_thread():
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads(_x: int) -> int:
        return max((p["num_threads"] for p in threadpool_info()), default=1)

    with threadpool_limits(2, user_api="blas"):  # the parent on two (the session runs one)
        assert fork_map(blas_threads, [0, 1], 2) == [1, 1]
