"""The local scheduler's rate limit (tacgen_lib.runtime.scheduler): with Snakemake's default
limit, every finished job leaves one more wake-up timer chain behind; without it none; and
only a local run's default limit is dropped."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest
from snakemake.scheduling.job_scheduler import JobRateLimiter
from snakemake.settings.types import MaxJobsPerTimespan

from tacgen_lib.runtime.scheduler import (
    DEFAULT_RATE_LIMIT,
    RATE_LIMITER_ATTRIBUTE,
    drop_local_rate_limit,
)

ROOT = Path(__file__).resolve().parents[2]
N_JOBS = 40

# A workflow of N_JOBS one-line shell jobs whose onsuccess counts the scheduler's timer
# threads still alive (threading.Timer: the scheduler's wake-ups). `drop` in the config
# applies the workflow's own onstart call.
SNAKEFILE = textwrap.dedent(
    f"""
    import threading
    from tacgen_lib.runtime.scheduler import drop_local_rate_limit

    rule all:
        input: expand("out/{{i}}.txt", i=range({N_JOBS}))

    rule one:
        output: "out/{{i}}.txt"
        shell: "echo {{wildcards.i}} > {{output}}"

    onstart:
        if config.get("drop"):
            drop_local_rate_limit(workflow.scheduler, local=workflow.local_exec)

    onsuccess:
        timers = sum(isinstance(t, threading.Timer) for t in threading.enumerate())
        with open("timers.txt", "w") as fh:
            fh.write(str(timers))
    """
)


def _timers_after_run(tmp_path: Path, drop: bool) -> int:
    work = tmp_path / ("dropped" if drop else "default")
    work.mkdir()
    (work / "Snakefile").write_text(SNAKEFILE)
    subprocess.run(
        [sys.executable, "-m", "snakemake", "--cores", "2", "--quiet", "all"]
        + (["--config", "drop=1"] if drop else []),
        cwd=work,
        check=True,
        capture_output=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=300,
    )
    return int((work / "timers.txt").read_text())


def test_default_limit_leaves_a_timer_chain_per_finished_job_and_dropping_it_leaves_none(
    tmp_path,
):
    # the bug the module works around, measured on the installed Snakemake: if a release
    # fixes it, this fails and the workaround can go
    kept = _timers_after_run(tmp_path, drop=False)
    assert kept >= N_JOBS // 2, f"{kept} timer threads after {N_JOBS} jobs"
    assert _timers_after_run(tmp_path, drop=True) == 0


def _scheduler(limit: str) -> SimpleNamespace:
    return SimpleNamespace(job_rate_limiter=JobRateLimiter(MaxJobsPerTimespan.parse_choice(limit)))


def test_the_default_is_snakemakes_default():
    from snakemake.cli import get_argument_parser

    default = get_argument_parser().get_default("max_jobs_per_timespan")
    parsed = MaxJobsPerTimespan.parse_choice(default)
    assert (parsed.max_jobs, parsed.timespan) == DEFAULT_RATE_LIMIT


def test_only_a_local_runs_default_limit_is_dropped():
    local = _scheduler("100/1s")
    assert drop_local_rate_limit(local, local=True)
    assert local.job_rate_limiter is None

    remote = _scheduler("100/1s")
    assert not drop_local_rate_limit(remote, local=False)
    assert remote.job_rate_limiter is not None

    chosen = _scheduler("10/1m")
    assert not drop_local_rate_limit(chosen, local=True)
    assert chosen.job_rate_limiter.max_jobs == 10


def test_a_scheduler_without_a_limit_is_left_alone():
    assert not drop_local_rate_limit(SimpleNamespace(job_rate_limiter=None), local=True)


def test_a_scheduler_without_the_attribute_is_left_alone_and_named():
    with pytest.warns(RuntimeWarning, match=RATE_LIMITER_ATTRIBUTE):
        assert not drop_local_rate_limit(SimpleNamespace(), local=True)


def test_the_installed_snakemake_has_the_private_attribute():
    """drop_local_rate_limit sets a private attribute of Snakemake's JobScheduler: a release
    that renames or removes it fails here, naming it (pyproject.toml pins the range)."""
    import inspect

    from snakemake.scheduling import job_scheduler

    init = inspect.getsource(job_scheduler.JobScheduler.__init__)
    assert f"self.{RATE_LIMITER_ATTRIBUTE} =" in init, (
        f"snakemake's JobScheduler.__init__ no longer sets {RATE_LIMITER_ATTRIBUTE!r}"
    )
    reads = inspect.getsource(job_scheduler.JobScheduler)
    assert reads.count(f"self.{RATE_LIMITER_ATTRIBUTE}") >= 3, (
        f"snakemake's JobScheduler no longer reads {RATE_LIMITER_ATTRIBUTE!r}"
    )
