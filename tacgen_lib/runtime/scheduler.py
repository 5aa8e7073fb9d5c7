"""The local job scheduler's rate limit, which costs a local run a share of a core.

Snakemake (9.x; `--max-jobs-per-timespan`, default 100/1s) limits how many jobs a run submits
per timespan. While that limit is set, every pass of its scheduling loop
(`JobScheduler.schedule`) ends by starting a `threading.Timer` that wakes the loop again one
timespan later, so the limit can be re-checked; that wake-up is itself a pass, which starts
the next timer. Each job that finishes wakes the loop once more and so starts one more such
chain, and no chain ever ends: after n finished jobs the loop runs about n passes per second,
and every pass checks the existence and size of every input file of every ready job. With
the `code` inputs that every rule declares (its scripts' import closure), a local run of the
default DAG spent about half a core in the scheduler by its 180th job, with over a hundred
timer threads alive (measured on a 2-core machine; `tests/runtime/test_scheduler.py` shows
the chains grow and the patch stops them).

A local run needs no submission rate limit: the cores already bound what runs at once, and
Snakemake before version ``8.17`` had none. `drop_local_rate_limit` removes it from a local run's
scheduler when it is Snakemake's default, before the first pass, so the loop wakes only when a
job finishes, as it did then. A rate limit given on the command line, and any cluster or cloud
executor's (whose submissions the limit exists to pace), are kept.
"""

from __future__ import annotations

import warnings
from typing import Any

__all__ = ["DEFAULT_RATE_LIMIT", "RATE_LIMITER_ATTRIBUTE", "drop_local_rate_limit"]

#: Snakemake's default `--max-jobs-per-timespan` (jobs, seconds).
DEFAULT_RATE_LIMIT = (100, 1)
#: The private attribute of Snakemake's `JobScheduler` that holds the limit (9.x). The
#: `workflow` extra of pyproject.toml pins the Snakemake range this holds for, and
#: tests/runtime/test_scheduler.py fails naming it if an installed release has no such
#: attribute.
RATE_LIMITER_ATTRIBUTE = "job_rate_limiter"


def drop_local_rate_limit(scheduler: Any, *, local: bool) -> bool:
    """Remove the submission rate limit from a local run's `JobScheduler` when it is
    Snakemake's default (`DEFAULT_RATE_LIMIT`). Call it before the scheduler's first pass
    (the workflow's `onstart`). Returns whether it was removed.

    Kept: a remote executor's limit (`local` False), a limit other than the default, and a
    scheduler without the attribute (another Snakemake version: nothing is changed, and a
    RuntimeWarning names the attribute)."""
    if not local:
        return False
    if not hasattr(scheduler, RATE_LIMITER_ATTRIBUTE):
        warnings.warn(
            f"Snakemake's job scheduler has no attribute {RATE_LIMITER_ATTRIBUTE!r} (another "
            "Snakemake release than pyproject.toml pins?): its submission rate limit is kept, "
            "and a local run's scheduler wakes more often (tacgen_lib.runtime.scheduler)",
            RuntimeWarning,
            stacklevel=2,
        )
        return False
    limiter = getattr(scheduler, RATE_LIMITER_ATTRIBUTE)
    if limiter is None:
        return False
    if (getattr(limiter, "max_jobs", None), getattr(limiter, "timespan", None)) != (
        DEFAULT_RATE_LIMIT
    ):
        return False
    setattr(scheduler, RATE_LIMITER_ATTRIBUTE, None)
    return True
