"""Policy stage: settings, cells, BC, evaluation statistics (against plain references)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml
from snakemake_run import ROOT, validated

from tacgen_lib.policy import bc, evaluate, policy_cells
from tacgen_lib.policy.settings import LEARNED_CONDITIONS, PolicySettings

SCHEMA = ROOT / "config" / "config.schema.yaml"


@pytest.mark.parametrize("overlay", [None, "test.yaml", "paper.yaml"])
def test_every_config_builds_policy_settings(overlay):
    cfg = validated(overlay)
    s = PolicySettings.from_config(cfg["policy"])
    assert s.n_demos == cfg["policy"]["n_demos"] and s.n_heldout == cfg["policy"]["n_heldout"]
    if overlay == "paper.yaml":
        assert (s.n_demos, s.n_heldout) == (96, 300)
        assert len(policy_cells.sweep_cells(s)) == 24  # H {128..1024} x E {200, 400} x 3 seeds


def test_policy_fields_are_schema_keys_with_equal_defaults():
    schema = yaml.safe_load(SCHEMA.read_text())["properties"]["policy"]["properties"]
    for f in dataclasses.fields(PolicySettings):
        assert f.name in schema, f.name
        default = schema[f.name]["default"]
        want = list(f.default) if isinstance(f.default, tuple) else f.default
        assert default == want, f.name


def test_policy_settings_refuse_bad_values():
    with pytest.raises(ValueError, match="policy.colour: unknown key"):
        PolicySettings.from_config({"colour": 1})
    with pytest.raises(ValueError, match="palpation_forces"):
        PolicySettings.from_config({"palpation_forces": [0.15, 5.0]})
    with pytest.raises(ValueError, match="window_ratio"):
        PolicySettings.from_config({"min_window_ratio": 4.0, "max_window_ratio": 3.0})


def test_cells_are_unique_and_matched():
    s = PolicySettings.tiny()
    all_cells = policy_cells.all_cells(s)
    assert len(set(all_cells)) == len(all_cells)
    main = policy_cells.main_cells(s)
    learned = [c for c in main if c[0] in LEARNED_CONDITIONS]
    assert {c[1:] for c in learned} == {(s.hidden, s.epochs, s.seeds[0])}  # matched capacity


def test_null_pairing_is_a_derangement_within_each_split():
    ids = np.array([f"e{i}" for i in range(10)])
    splits = np.array(["train"] * 6 + ["test"] * 4)
    idx = bc.null_pairing(ids, splits, seed=3)
    assert np.all(idx != np.arange(10))
    assert np.all(splits[idx] == splits)
    assert sorted(idx) == list(range(10))


def test_bc_fit_is_reproducible_and_learns():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(64, 5))
    force = np.exp(0.8 * x[:, 0])
    kw = dict(hidden=32, layers=3, epochs=150, lr=3e-3, weight_decay=0.0, batch_size=16, seed=1)
    kw["device"] = "cpu"
    a, la = bc.fit_bc(x, force, **kw)
    b, lb = bc.fit_bc(x, force, **kw)
    assert la == lb
    assert np.array_equal(a.grip_force(x), b.grip_force(x))
    assert la[-1] < 0.2 * la[0]
    assert np.corrcoef(np.log(a.grip_force(x)), np.log(force))[0, 1] > 0.95


def test_paired_delta_ci_matches_a_loop_reference():
    rng = np.random.default_rng(2)
    a = rng.random(50) < 0.7
    b = rng.random(50) < 0.4
    d, lo, hi = evaluate.paired_delta_ci(a, b, 500, seed=4)
    idx = np.random.default_rng([4, 0xB007]).integers(0, 50, size=(500, 50))
    ref = [a[i].mean() - b[i].mean() for i in idx]  # both scored on the same resample
    assert d == pytest.approx(a.mean() - b.mean())
    assert lo == pytest.approx(np.quantile(ref, 0.025))
    assert hi == pytest.approx(np.quantile(ref, 0.975))
    with pytest.raises(ValueError, match="same episodes"):
        evaluate.paired_delta_ci(a, b[:-1], 10, seed=0)


def test_success_ci_and_failure_counts():
    s, lo, hi = evaluate.success_ci(np.array([1, 1, 0, 1]), 1000, seed=0)
    assert s == 0.75 and 0 <= lo <= s <= hi <= 1
    counts = evaluate.failure_counts(np.array(["success", "slip", "slip", "crush"]))
    assert counts == {"success": 1, "slip": 2, "crush": 1, "drop": 0, "miss": 0}
    with pytest.raises(ValueError, match="unknown outcome"):
        evaluate.failure_counts(np.array(["wobble"]))


def test_gap_closed():
    assert evaluate.gap_closed(0.3, 0.2, 0.9) == pytest.approx(0.1 / 0.7)
    assert np.isnan(evaluate.gap_closed(0.3, 0.5, 0.4))


def test_grip_force_regression_finds_information_only_touch_has():
    rng = np.random.default_rng(5)
    n = 160
    v = rng.normal(size=(n, 4))
    t = rng.normal(size=(n, 3))
    y = 0.2 * v[:, 0] + t[:, 0] + 0.1 * rng.normal(size=n)
    train = np.arange(n) < 100
    res = evaluate.grip_force_regression(v, np.hstack([v, t]), y, train, 500, seed=0)
    assert res["delta_r2"] > 0.5 and res["ci_low"] > 0.3
    # a null T (independent of y) does not help
    null = evaluate.grip_force_regression(
        v, np.hstack([v, rng.normal(size=(n, 3))]), y, train, 500, seed=0
    )
    assert null["ci_low"] < 0.05
