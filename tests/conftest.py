"""Fixtures every test module shares.

Helpers for running the workflow live in `snakemake_run.py` and the real-data fixture writers
in `fixtures_real.py` (plain modules: pytest puts tests/ on sys.path).
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch


@pytest.fixture(autouse=True)
def one_torch_thread() -> Iterator[None]:
    """One intra-op torch thread: the tests' tensors are small, and on a loaded 2-core machine
    OpenMP spin-waits of a second thread cost more than they give. Restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
