"""Fusion variants of V and T features: values against plain float64 references."""

from __future__ import annotations

import numpy as np
import pytest

from tacgen_lib.probes.fusion import FUSIONS, fuse, fusion_table


def pair(n=9, d=5, seed=0):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, d)), 3.0 * rng.standard_normal((n, d))


def test_table_lists_the_paper_variants():
    assert set(FUSIONS) == {
        "concat",
        "mean",
        "max",
        "weighted_75_25",
        "weighted_25_75",
    }
    rows = fusion_table()
    assert [r["name"] for r in rows] == list(FUSIONS)
    assert all(r["description"] and r["inputs"] for r in rows)


def test_values_against_references():
    v, t = pair()
    np.testing.assert_array_equal(fuse("concat", v, t), np.hstack([v, t]))
    np.testing.assert_allclose(fuse("mean", v, t), (v + t) / 2)
    np.testing.assert_array_equal(fuse("max", v, t), np.where(v > t, v, t))
    np.testing.assert_allclose(fuse("weighted_75_25", v, t), 0.75 * v + 0.25 * t)
    np.testing.assert_allclose(fuse("weighted_25_75", v, t), 0.25 * v + 0.75 * t)


def test_attention_is_dropped_with_the_reason():
    """Issue 17: parameter-free attention over unit-norm tokens was 'mean' under another name."""
    v, t = pair()
    with pytest.raises(ValueError, match=r"'attention' was dropped.*equals 'mean'"):
        fuse("attention", v, t)
    assert "attention" not in FUSIONS


def test_a_constant_gate_is_nested_in_concat():
    """Why no learned gate: g v + (1 - g) t with g fixed over rows is a linear map of [v, t],
    so a linear probe on it is a linear probe on concat with tied coefficients."""
    v, t = pair()
    g = np.random.default_rng(3).random(v.shape[1])
    w = np.random.default_rng(4).standard_normal(v.shape[1])
    gated = (g * v + (1 - g) * t) @ w
    np.testing.assert_allclose(gated, fuse("concat", v, t) @ np.concatenate([g * w, (1 - g) * w]))


@pytest.mark.parametrize("name", sorted(FUSIONS))
def test_row_wise_so_permuting_pairs_commutes(name):
    v, t = pair(seed=2)
    p = np.random.default_rng(1).permutation(v.shape[0])
    np.testing.assert_array_equal(fuse(name, v[p], t[p]), fuse(name, v, t)[p])
    assert fuse(name, v, t).shape[1] == FUSIONS[name].dim(v.shape[1], t.shape[1])


def test_errors_say_what_to_do():
    v, t = pair()
    with pytest.raises(ValueError, match=r"unknown fusion 'sum'"):
        fuse("sum", v, t)
    with pytest.raises(ValueError, match=r"equal dimension.*use the aligned projections"):
        fuse("mean", v, np.ones((v.shape[0], 7)))
    with pytest.raises(ValueError, match=r"join them on sample_id"):
        fuse("concat", v, t[:-1])
    assert fuse("concat", v, np.ones((v.shape[0], 7))).shape == (v.shape[0], 12)
