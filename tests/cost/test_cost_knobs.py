"""The simulation and features knobs' metrics and cost points (tacgen_lib.cost.knob_metrics,
scores) against plain references."""

import numpy as np
import pandas as pd
import pytest
from sklearn.metrics import accuracy_score, r2_score

from tacgen_lib.cost.knob_metrics import (
    KnobSetting,
    features_metric_ids,
    features_metrics,
    force_band_width,
    knob_points,
    metric_row,
)
from tacgen_lib.cost.points import POINT_COLUMNS
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap, resample_indices
from tacgen_lib.probes.score_ci import score_ci
from tacgen_lib.runtime.benchmarks import Benchmark


@pytest.mark.parametrize("metric", ["r2", "accuracy"])
def test_score_ci_matches_a_loop_over_the_same_resamples(metric):
    rng = np.random.default_rng(0)
    if metric == "r2":
        y = rng.normal(size=60)
        pred = y + rng.normal(scale=0.5, size=60)
        ref_score = r2_score
    else:
        y = rng.choice(np.array(["a", "b", "c"], dtype=object), size=60)
        pred = np.where(rng.random(60) < 0.7, y, "a").astype(object)
        ref_score = accuracy_score
    value, lo, hi = score_ci(metric, y, pred, n_resamples=300, seed=5)
    idx = resample_indices(60, 300, 5)
    scores = [ref_score(y[i], pred[i]) for i in idx]
    assert value == pytest.approx(ref_score(y, pred))
    assert (lo, hi) == pytest.approx(tuple(np.quantile(scores, [0.025, 0.975])), abs=1e-12)
    assert lo <= value <= hi


def test_score_ci_uses_the_resamples_of_the_delta_ci():
    """With V a constant predictor, Delta's resampled values are V+T's score minus a fixed
    per-resample baseline: both CIs come from one draw of test rows (same seed)."""
    rng = np.random.default_rng(1)
    y = rng.choice(np.array(["x", "y"], dtype=object), size=40)
    pred = np.where(rng.random(40) < 0.8, y, "x").astype(object)
    never = np.full(40, "z", dtype=object)  # accuracy 0 on every resample
    boot = fixed_test_bootstrap(y, never, pred, "accuracy", n_resamples=500, seed=3)
    _, lo, hi = score_ci("accuracy", y, pred, n_resamples=500, seed=3)
    assert (lo, hi) == pytest.approx((boot["ci_low"], boot["ci_high"]))


def test_score_ci_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="equal 1-D"):
        score_ci("r2", np.zeros(5), np.zeros(4), n_resamples=10, seed=0)


def test_force_band_width_is_the_mean_width_with_a_bootstrap_ci():
    rng = np.random.default_rng(2)
    p05 = rng.uniform(0.4, 0.5, 200)
    p95 = p05 + rng.uniform(0.0, 0.2, 200)
    mean, lo, hi = force_band_width(p05, p95, n_resamples=1000, seed=0)
    assert mean == pytest.approx(np.mean(p95 - p05))
    assert lo < mean < hi and hi - lo < 0.02
    with pytest.raises(ValueError, match="row 3"):
        force_band_width(np.array([0, 0, 0, 1.0]), np.array([1, 1, 1, 0.5]), n_resamples=10, seed=0)


def _pvr_table() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "modality": ["vision", "tactile"],
            "target": ["shape", "hardness"],
            "delta": [0.02, -0.01],
            "ci_low": [-0.01, -0.05],
            "ci_high": [0.05, 0.03],
            "pretrained_accuracy": [0.62, 0.80],
            "pretrained_ci_low": [0.55, 0.74],
            "pretrained_ci_high": [0.68, 0.85],
            "random_accuracy": [0.60, 0.81],
            "random_ci_low": [0.53, 0.75],
            "random_ci_high": [0.66, 0.86],
        }
    )


def test_features_metrics_report_the_backbone_in_use():
    for pretraining, acc in ((True, 0.80), (False, 0.81)):
        rows = {
            r["metric_id"]: r
            for r in features_metrics(_pvr_table(), pretraining=pretraining, n_resamples=100)
        }
        delta_id, acc_id = features_metric_ids("tactile", "hardness")
        assert rows[acc_id]["value"] == acc
        assert (rows[delta_id]["value"], rows[delta_id]["ci_low"]) == (-0.01, -0.05)
    with pytest.raises(ValueError, match="random_ci_low"):
        features_metrics(
            _pvr_table().drop(columns="random_ci_low"), pretraining=False, n_resamples=100
        )


def _setting(label: str, value: float, walls: list[float], default: bool = False) -> KnobSetting:
    metrics = pd.DataFrame(
        [
            metric_row("m1", value, value - 0.1, value + 0.1, "ci"),
            metric_row("m2", 2 * value, 2 * value, 2 * value, "ci"),
        ]
    )
    return KnobSetting(
        float(label), label, default, metrics, [Benchmark(w, w / 2, 100.0) for w in walls]
    )


def test_knob_points_sum_benchmarks_and_keep_metric_order():
    settings = [_setting("2", 0.5, [1.0, 2.0]), _setting("8", 0.7, [3.0, 4.0, 5.0], True)]
    points = knob_points("presses", "corpus", settings, ["m2", "m1"])
    assert list(points.columns) == [*POINT_COLUMNS, "direction"]  # check_points adds direction
    assert list(points["metric"]) == ["m2", "m1", "m2", "m1"]
    assert list(points["wall_s"]) == [3.0, 3.0, 12.0, 12.0]
    assert list(points["cpu_s"]) == [1.5, 1.5, 6.0, 6.0]
    assert list(points["n_jobs"]) == [2, 2, 3, 3]
    assert list(points["is_default"]) == [False, False, True, True]


def test_knob_points_refuse_missing_metrics_benchmarks_and_duplicates():
    s = _setting("2", 0.5, [1.0])
    with pytest.raises(ValueError, match="'m3'"):
        knob_points("presses", "corpus", [s], ["m3"])
    with pytest.raises(ValueError, match="no benchmark"):
        knob_points("presses", "corpus", [KnobSetting(2.0, "2", False, s.metrics, [])])
    with pytest.raises(ValueError, match="duplicate"):
        knob_points("presses", "corpus", [s, s])
