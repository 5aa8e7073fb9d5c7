"""The force bands against the true force (tacgen_lib.corpus.force_bands): R^2 equal to
scikit-learn's, coverage and its Wilson interval by hand, the shuffled control a derangement,
and the hard cases refused by name."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from sklearn.metrics import r2_score

from tacgen_lib.corpus.force_bands import corpus_force_bands, force_band_check


def bands(n=400, seed=0):
    rng = np.random.default_rng(seed)
    true = rng.uniform(1.0, 5.0, n)
    p50 = true * (1 + 0.05 * rng.standard_normal(n))
    width = 0.2 * true
    return true, p50 - width, p50, p50 + width


def test_r2_coverage_and_the_shuffled_control():
    true, p05, p50, p95 = bands()
    got = force_band_check(true, p05, p50, p95, seed=3)
    assert got.n == 400
    assert got.r2 == pytest.approx(r2_score(true, p50), rel=1e-12)
    inside = (true >= p05) & (true <= p95)
    assert got.coverage == inside.mean()
    # Wilson 95 % interval by its formula
    z, k, n = 1.959963984540054, inside.sum(), 400
    centre = (k / n + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(k / n * (1 - k / n) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert (got.coverage_low, got.coverage_high) == pytest.approx((centre - half, centre + half))
    assert got.mean_width == pytest.approx(np.mean(p95 - p05))
    # another sample's force lands in a band of this width far less often, and p50 does not
    # predict it
    assert got.shuffled_coverage < got.coverage_low and got.shuffled_r2 < 0
    again = force_band_check(true, p05, p50, p95, seed=3)
    assert again == got


def test_the_shuffled_forces_are_a_derangement():
    """With bands that hold only their own row's force exactly, the shuffled coverage is 0."""
    true = np.arange(1.0, 51.0)
    got = force_band_check(true, true, true, true, seed=7)
    assert got.coverage == 1.0 and got.shuffled_coverage == 0.0
    assert force_band_check(true[:2], true[:2], true[:2], true[:2], seed=1).shuffled_coverage == 0


def test_rows_without_a_true_force_are_left_out_and_bad_bands_refused():
    true, p05, p50, p95 = bands(50)
    true[:10] = np.nan  # a real corpus's rows: no simulated force
    assert force_band_check(true, p05, p50, p95, seed=0).n == 40
    with pytest.raises(ValueError, match="need >= 2 rows with a true force, got 1"):
        force_band_check(true[9:11], p05[9:11], p50[9:11], p95[9:11], seed=0)
    p05[20] = p95[20] + 1.0
    with pytest.raises(ValueError, match="row 20 has p05"):
        force_band_check(true, p05, p50, p95, seed=0)
    with pytest.raises(ValueError, match="differ in length"):
        force_band_check(true, p05[:-1], p50, p95, seed=0)


def test_a_corpus_without_true_forces_has_no_check():
    """A real corpus's edge has no force columns (or no values in them): None, not an error."""
    true, p05, p50, p95 = bands(20)
    frame = pd.DataFrame(
        {"force_normal": true, "force_p05": p05, "force_p50": p50, "force_p95": p95}
    )
    assert corpus_force_bands(frame, seed=0) == force_band_check(true, p05, p50, p95, seed=0)
    assert corpus_force_bands(frame.drop(columns=["force_normal"]), seed=0) is None
    assert corpus_force_bands(frame.assign(force_normal=float("nan")), seed=0) is None
    assert corpus_force_bands(pd.DataFrame({"sample_id": ["a", "b"]}), seed=0) is None
    # one press per sample (a scene without press_jitter): no band, nothing to cover
    one_press = frame.assign(force_p05=true, force_p50=true, force_p95=true)
    assert corpus_force_bands(one_press, seed=0) is None
