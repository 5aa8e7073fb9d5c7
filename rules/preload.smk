"""The preloaded interpreter (tacgen_lib.runtime.preload): on a local run, one server per
Snakemake process imports torch, scikit-learn, scipy and pandas once, and every script job
forks from it instead of importing them again. Cluster executors never start it (their jobs
run where the server is not); TACGEN_PRELOAD=0 turns it off."""

from tacgen_lib.runtime.preload import (
    start_preloaded_interpreter,
    stop_preloaded_interpreter,
)

PRELOAD_SERVER = {}


onstart:
    if workflow.local_exec:
        PRELOAD_SERVER["process"] = start_preloaded_interpreter()


onsuccess:
    stop_preloaded_interpreter(PRELOAD_SERVER.pop("process", None))


onerror:
    stop_preloaded_interpreter(PRELOAD_SERVER.pop("process", None))
