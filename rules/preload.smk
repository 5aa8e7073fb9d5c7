"""The preloaded interpreter (tacgen_lib.runtime.preload, .preload_server): on a local run, one server per
Snakemake process imports torch, scikit-learn, scipy and pandas once, and every script job
forks from it instead of importing them again. Cluster executors never start it (their jobs
run where the server is not), nor does a run of a few jobs (MIN_JOBS); TACGEN_PRELOAD=0 turns
it off.

The same `onstart` drops Snakemake's default submission rate limit from a local run's scheduler
(tacgen_lib.runtime.scheduler: its wake-up timers multiply with every finished job)."""

from tacgen_lib.runtime.preload_server import (
    start_preloaded_interpreter,
    stop_preloaded_interpreter,
)
from tacgen_lib.runtime.scheduler import drop_local_rate_limit

PRELOAD_SERVER = {}


onstart:
    drop_local_rate_limit(workflow.scheduler, local=workflow.local_exec)
    # len(workflow.dag): the jobs this run will run (Snakemake's "Nothing to be done" test)
    PRELOAD_SERVER["process"] = start_preloaded_interpreter(
        len(workflow.dag), local=workflow.local_exec
    )


onsuccess:
    stop_preloaded_interpreter(PRELOAD_SERVER.pop("process", None))


onerror:
    stop_preloaded_interpreter(PRELOAD_SERVER.pop("process", None))
