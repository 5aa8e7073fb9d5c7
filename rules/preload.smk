"""The preloaded interpreter (tacgen_lib.runtime.preload): on a local run, one server per
Snakemake process imports torch, scikit-learn, scipy and pandas once, and every script job
forks from it instead of importing them again. Cluster executors never start it (their jobs
run where the server is not), nor does a run of a few jobs (MIN_JOBS); TACGEN_PRELOAD=0 turns
it off."""

from tacgen_lib.runtime.preload import (
    start_preloaded_interpreter,
    stop_preloaded_interpreter,
)

PRELOAD_SERVER = {}


onstart:
    # len(workflow.dag): the jobs this run will run (Snakemake's "Nothing to be done" test)
    PRELOAD_SERVER["process"] = start_preloaded_interpreter(
        len(workflow.dag), local=workflow.local_exec
    )


onsuccess:
    stop_preloaded_interpreter(PRELOAD_SERVER.pop("process", None))


onerror:
    stop_preloaded_interpreter(PRELOAD_SERVER.pop("process", None))
