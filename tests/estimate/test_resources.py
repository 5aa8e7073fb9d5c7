"""SLURM time limits from the run-time estimate (tacgen_lib.estimate.resources): the headroom,
the floor and the attempt factor; a rule the estimate cannot price keeps its own runtime; the
rules of the workflow get the estimate's function, a runtime set from outside wins."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from snakemake.iocontainers import Wildcards
from snakemake.resources import Resources
from snakemake_run import hand_config

from tacgen_lib.estimate.calibration import MissingCalibrationError
from tacgen_lib.estimate.resources import (
    HEADROOM,
    MIN_RUNTIME_S,
    attach_estimated_runtime,
    estimated_runtime,
    predicted_seconds,
    requested_runtime,
)


def test_requested_runtime_headroom_floor_and_attempt():
    hours = 3 * 3600.0
    assert requested_runtime(hours) == 60 * 3 * HEADROOM  # minutes
    assert requested_runtime(hours, attempt=3) == 3 * requested_runtime(hours)
    assert requested_runtime(1.0) == MIN_RUNTIME_S / 60  # the floor
    assert requested_runtime(0.0) * 60 >= MIN_RUNTIME_S
    # rounded up to a whole minute, never below headroom x the estimate
    for s in (601.0, 1234.5, 86_399.0):
        assert requested_runtime(s) * 60 >= HEADROOM * s
        assert requested_runtime(s) * 60 < HEADROOM * s + 60
    with pytest.raises(ValueError, match="attempt"):
        requested_runtime(10.0, attempt=0)
    with pytest.raises(ValueError, match="seconds"):
        requested_runtime(float("nan"))


def test_estimated_runtime_prices_a_job_and_falls_back_where_it_cannot():
    config = hand_config({"c": {"n": 1200}})
    runtime = estimated_runtime("merge_corpus", config, fallback=7)
    w = Wildcards(fromdict={"corpus": "c"})
    seconds = predicted_seconds("merge_corpus", config, {"corpus": "c"}, 1)
    assert runtime(w, 1, 1) == requested_runtime(seconds)
    assert runtime(w, 1, 2) == requested_runtime(seconds, 2)
    # a cost class without calibration points: the rule's own runtime x attempt
    vision = {"arch": "vit_tiny", "objective": "x", "checkpoint": None, "image_size": None}
    family = hand_config(backbones={"probes": [], "families": {"f": {"vision": vision}}})
    wf = {"family": "f", "modality": "vision"}
    guarded = estimated_runtime("family_backbone", family, fallback=30)
    assert guarded(Wildcards(fromdict=wf), 1, 2) == 60
    with pytest.raises(MissingCalibrationError, match="family_backbone:x"):
        estimated_runtime("family_backbone", family)(Wildcards(fromdict=wf), 1, 1)


def fake_rule(name, config, *, norun=False, runtime=30):
    return SimpleNamespace(
        name=name,
        norun=norun,
        module_globals={"config": config},
        resources=Resources.from_mapping({"runtime": runtime, "mem_mb": 1000}),
    )


def test_attach_gives_every_priced_rule_the_estimate_and_keeps_a_set_runtime():
    cfg = hand_config({"c": {"n": 100}})
    setting = {**cfg, "cost": {"setting": {"module": "cost_presses_2"}}}
    rules = [
        fake_rule("merge_corpus", cfg),
        fake_rule("make_splits", cfg),
        fake_rule("cost_presses_2_merge_corpus", setting),  # a cost setting's copy
        fake_rule("all", cfg, norun=True),
        fake_rule("not_a_rule_of_units", cfg),
    ]
    done = attach_estimated_runtime(rules, keep={"make_splits": {"runtime": 5}})
    assert done == ["merge_corpus", "cost_presses_2_merge_corpus"]
    assert rules[0].resources["runtime"].is_evaluable()
    assert not rules[1].resources["runtime"].is_evaluable()  # kept as set
    assert not rules[3].resources["runtime"].is_evaluable()
    assert rules[2].resources["mem_mb"].value == 1000  # memory is not the estimate's
