"""Each job's `runtime` resource (its SLURM time limit) from its run-time estimate.

What the run-time estimate predicts for one job (`tacgen_lib.estimate.predict.job_prediction`:
its rule's units line fitted on the shipped calibration, its own config, wildcards and
threads), with headroom, times the attempt:

    runtime [min] = ceil(max(MIN_RUNTIME_S, HEADROOM × predicted seconds) × attempt / 60)

so a limit is never below its estimate, and a job that runs out of time is resubmitted
(profiles/slurm `retries:`) with twice, then three times, as long. The prediction is in the
calibration CPU's seconds (the slower, 2-core class without AVX-512), so a cluster node is
usually faster than it; HEADROOM covers the scatter of the fitted lines (their spread, a few
tens of per cent) and a node up to twice as slow. Lines the calibration could not identify
(flagged `*` by `make estimate`) are lower bounds: their jobs rely on MIN_RUNTIME_S and the
attempt factor.

The workflow attaches `estimated_runtime` to every rule at parse time (`attach_estimated_runtime`,
called at the end of the Snakefile); Snakemake evaluates it per job, when it sizes the job.
Nothing is computed at parse time but the attachment: the calibration is read and fitted once,
on the first job evaluated. A runtime given for a rule with `--set-resources` (or a profile's
`set-resources:`) wins. Memory (`mem_mb`) is not estimated: the benchmark files sample a job's
peak memory too sparsely to fit on (tacgen_lib.runtime.benchmarks), so it stays per rule in the
profile.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = [
    "HEADROOM",
    "MIN_RUNTIME_S",
    "attach_estimated_runtime",
    "estimated_runtime",
    "predicted_seconds",
    "requested_runtime",
]

#: requested / predicted seconds (before the attempt factor)
HEADROOM = 2.0
#: the shortest limit asked for: SLURM's start-up and a loaded node's slow start fit in it
MIN_RUNTIME_S = 600.0


def requested_runtime(seconds: float, attempt: int = 1) -> int:
    """Minutes a job predicted to take `seconds` asks for on its `attempt` (1, 2, ...):
    max(MIN_RUNTIME_S, HEADROOM × seconds) × attempt, rounded up to a whole minute."""
    if not seconds >= 0:
        raise ValueError(f"predicted seconds must be >= 0, got {seconds}")
    if attempt < 1:
        raise ValueError(f"attempt must be >= 1, got {attempt}")
    return math.ceil(max(MIN_RUNTIME_S, HEADROOM * float(seconds)) * int(attempt) / 60.0)


@functools.cache
def _shipped_lines() -> dict[str, Any]:
    """The shipped calibration's lines (config/cost_calibration), fitted once per process."""
    from tacgen_lib.estimate.calibration import fit_costs, load_calibration

    return fit_costs(load_calibration().points)


def predicted_seconds(
    rule: str, config: Mapping[str, Any], wildcards: Mapping[str, str], threads: int
) -> float:
    """The run-time estimate of one job of `rule` (the main rule's name) under `config` (the
    job's own: a cost setting's module's config for its jobs), from the shipped calibration."""
    from tacgen_lib.estimate.predict import job_prediction

    wildcards = {k: str(v) for k, v in wildcards.items()}  # Snakemake's Wildcards, or a dict
    return job_prediction(rule, config, wildcards, int(threads), _shipped_lines())[2]


def estimated_runtime(
    rule: str, config: Mapping[str, Any], fallback: int | None = None
) -> Callable[..., int]:
    """A Snakemake resource function of `rule`'s jobs: (wildcards, threads, attempt) -> the
    minutes `requested_runtime` gives the job's `predicted_seconds`. Where the estimate cannot
    price the job (a cost class the calibration has not measured, a config its units line
    cannot count), `fallback` × attempt minutes, the rule's own runtime, so that a run never
    stops for want of an estimate (`make estimate` names what is missing); without a fallback
    the estimate's error is raised."""
    from tacgen_lib.estimate.calibration import MissingCalibrationError
    from tacgen_lib.estimate.units import MissingUnitsError

    def runtime(wildcards: Any, threads: int, attempt: int) -> int:
        try:
            seconds = predicted_seconds(rule, config, wildcards, threads)
        except (MissingCalibrationError, MissingUnitsError):
            if fallback is None:
                raise
            return int(fallback) * int(attempt)
        return requested_runtime(seconds, attempt)

    runtime.__name__ = f"estimated_runtime_{rule}"
    return runtime


def attach_estimated_runtime(rules: Iterable[Any], *, keep: Mapping[str, Any]) -> list[str]:
    """Give every rule that runs and has a units line (`tacgen_lib.estimate.units.UNITS`) its
    `estimated_runtime`, but a rule named in `keep` with a `runtime` (Snakemake's
    `--set-resources`, a profile's `set-resources:`). A cost setting's rules (a Snakemake
    module) are priced as their main rule under the module's config. Returns the names of
    the rules given one."""
    from tacgen_lib.estimate.dag import base_rule
    from tacgen_lib.estimate.units import UNITS

    attached = []
    for rule in rules:
        if rule.norun or "runtime" in (keep.get(rule.name) or {}):
            continue
        config = (getattr(rule, "module_globals", None) or {}).get("config") or {}
        name = base_rule(rule.name, config)
        if name not in UNITS:
            continue
        own = rule.resources.get("runtime")  # the rule's resources: or default-resources
        fallback = own.value if own is not None and isinstance(own.value, int) else None
        rule.resources["runtime"] = estimated_runtime(name, config, fallback)
        attached.append(rule.name)
    return attached
