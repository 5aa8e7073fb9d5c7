"""Fixtures every test module shares.

Helpers for running the workflow live in `snakemake_run.py` and the real-data fixture writers
in `fixtures_real.py` (plain modules: pytest puts tests/ on sys.path).
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch
from snakemake_run import copy_tree, smk


@pytest.fixture(autouse=True)
def one_torch_thread() -> Iterator[None]:
    """One intra-op torch thread: the tests' tensors are small, and on a loaded 2-core machine
    OpenMP spin-waits of a second thread cost more than they give. Restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def reference_run(tmp_path_factory) -> Path:
    """One clean cold run of config/test.yaml in a copy of the repository, shared by every
    module that needs finished edges (workflow, faults). Tests copy it (`copy_run`) before
    changing anything; they never change it."""
    work = copy_tree(tmp_path_factory.mktemp("reference") / "run")
    smk(work)
    return work


@pytest.fixture(scope="session")
def cold_dry_run(tmp_path_factory) -> subprocess.CompletedProcess:
    """`snakemake --dry-run` of config/test.yaml in a fresh copy of the repository (nothing
    built), run once for every module that reads its plan (workflow, cost, code inputs)."""
    return smk(copy_tree(tmp_path_factory.mktemp("dry") / "run"), "--dry-run")
