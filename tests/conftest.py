"""Fixtures every test module shares.

Helpers for running the workflow live in `snakemake_run.py` and the real-data fixture writers
in `fixtures_real.py` (plain modules: pytest puts tests/ on sys.path).
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import torch
from faults_run import kill_series
from filelock import FileLock
from hypothesis import settings
from snakemake_run import ROOT, copy_tree, smk

# CI (CI=true) draws the same hypothesis examples every run, so a run's outcome depends on the
# code alone; elsewhere each run explores new ones, and what fails becomes an @example
settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

#: fixtures that run Snakemake: a test that uses one is a workflow test (marked `workflow`, left
#: out of the kernel variants, tools/kernel_variants.py)
WORKFLOW_FIXTURES = {"reference_run", "resumed_run", "cold_dry_run", "align_run", "probes_run"}


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--torch-threads",
        type=int,
        default=1,
        help="torch intra-op threads in every test (default 1; the kernel variants also run 2)",
    )


def pytest_configure(config: pytest.Config) -> None:
    """numpy's OpenBLAS on one thread, as torch (`torch_threads`), unless the environment names
    its count (the kernel variants run two, tools/kernel_variants.py): the tests' matrices are
    small, and on a loaded 2-core machine a second OpenBLAS thread spin-waits after every call
    it joins, taking CPU time from the other test processes and the workflow runs."""
    if "OPENBLAS_NUM_THREADS" not in os.environ:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")


def pytest_report_header(config: pytest.Config) -> str:
    """The kernels this session's numpy, OpenBLAS and torch use: a float comparison that holds
    on one set and not another is a defect of the test or the code (docs/tests.md)."""
    sys.path.insert(0, str(ROOT / "tools"))
    from kernel_variants import active_kernels

    kernels = {**active_kernels(), "torch_threads": config.getoption("--torch-threads")}
    return f"kernels: {kernels}"


#: the test modules with the longest workflow runs, started first (in this order), so that no
#: worker is left running one of them alone at the end of the session
LONG_FIRST = (
    "test_slurm.py",
    "test_faults.py",
    "test_cost_features_workflow.py",
    "test_cost_workflow.py",
    "test_probes_workflow.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark workflow tests, and order the modules for pytest-xdist. `make test` runs
    `-n 2 --dist loadfile --no-loadscope-reorder`: each module stays on one worker (its
    module-scoped runs are built once), the modules are handed out in this order (the long
    workflow modules first, then those with other workflow tests, then the rest), and the
    session's shared runs (`reference_run`, `resumed_run`) are built once for all workers
    (`shared_run`). (pytest-xdist's `loadgroup` does not group under pytest 9: the group
    suffix it writes into a node id is not kept.)"""

    for item in items:
        if WORKFLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.workflow)
    runs_workflow = {i.path.name for i in items if i.get_closest_marker("workflow")}

    def rank(item: pytest.Item) -> tuple[int, int]:
        name = item.path.name
        if name in LONG_FIRST:
            return (0, LONG_FIRST.index(name))
        return (1 if name in runs_workflow else 2, 0)

    items.sort(key=rank)  # stable: collection order within a rank


@pytest.fixture(autouse=True)
def torch_threads(request: pytest.FixtureRequest) -> Iterator[None]:
    """One intra-op torch thread unless `--torch-threads` says otherwise: the tests' tensors
    are small, and on a loaded 2-core machine OpenMP spin-waits of a second thread cost more
    than they give. Restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(request.config.getoption("--torch-threads"))
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def reference_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One clean cold run of config/test.yaml in a copy of the repository, shared by every
    module that needs finished edges (workflow, faults, cost, SLURM). Tests copy it
    (`copy_run`) before changing anything; they never change it."""
    return shared_run(tmp_path_factory, "reference", lambda work: smk(copy_tree(work)))[0]


@pytest.fixture(scope="session")
def resumed_run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """A second cold run of config/test.yaml in its own copy of the repository, killed with
    SIGKILL during every stage and resumed each time with `make resume`'s tool, to the end
    (faults_run.kill_series). Every edge in it is computed again, in another directory, by the
    same code with the same config and thread counts: the fault tests check what each kill
    left, and the determinism test compares its edges with `reference_run`'s bit for bit."""
    return shared_run(tmp_path_factory, "resumed", lambda work: kill_series(copy_tree(work)))[1]


def shared_run(
    factory: pytest.TempPathFactory, name: str, build: Callable[[Path], object]
) -> tuple[Path, object]:
    """`build(work)` once per test session, whatever the number of pytest-xdist workers, and
    its (picklable) result. The workers share the parent of their base temporary directory;
    a file lock there lets the first worker that needs the run build it while the others
    wait. A failed build is recorded, so the others fail at once with its error instead of
    building again."""
    base = factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    work, result, failed = root / name / "run", root / f"{name}.pickle", root / f"{name}.failed"
    with FileLock(str(root / f"{name}.lock")):
        if failed.exists():
            raise RuntimeError(
                f"the shared {name} run failed in another worker:\n{failed.read_text()}"
            )
        if not result.exists():
            try:
                value = build(work)
            except BaseException as err:
                failed.write_text(str(err)[-20000:])
                raise
            result.write_bytes(pickle.dumps(value))
    return work, pickle.loads(result.read_bytes())


@pytest.fixture(scope="session")
def cold_dry_run(tmp_path_factory) -> subprocess.CompletedProcess:
    """`snakemake --dry-run` of config/test.yaml in a fresh copy of the repository (nothing
    built), run once for every module that reads its plan (workflow, cost, code inputs)."""
    return smk(copy_tree(tmp_path_factory.mktemp("dry") / "run"), "--dry-run")
