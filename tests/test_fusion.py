"""Fusion variants of V and T features: values against plain float64 references."""

from __future__ import annotations

import numpy as np
import pytest

from tacgen_lib.probes.fusion import FUSIONS, fuse, fusion_table


def pair(n=9, d=5, seed=0):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, d)), 3.0 * rng.standard_normal((n, d))


def attention_reference(v, t):
    """Plain loop: tokens X = [v; t], A = softmax(X X^T / sqrt(d)) rows, mean of A X."""
    out = np.empty_like(v)
    for i in range(v.shape[0]):
        x = np.stack([v[i], t[i]])
        s = x @ x.T / np.sqrt(x.shape[1])
        a = np.exp(s - s.max(axis=1, keepdims=True))
        a /= a.sum(axis=1, keepdims=True)
        out[i] = (a @ x).mean(axis=0)
    return out


def test_table_lists_the_paper_variants():
    assert set(FUSIONS) == {
        "concat", "mean", "max", "attention", "weighted_75_25", "weighted_25_75",
    }  # fmt: skip
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
    np.testing.assert_allclose(fuse("attention", v, t), attention_reference(v, t), rtol=1e-12)


def test_attention_is_mean_for_equal_norms_and_stays_finite_for_huge_scores():
    v, t = pair()
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    np.testing.assert_allclose(fuse("attention", v, t), fuse("mean", v, t), rtol=1e-12)
    big = fuse("attention", 1e4 * v, t)  # scores ~1e8: a naive exp overflows
    assert np.isfinite(big).all()
    np.testing.assert_allclose(big, attention_reference(1e4 * v, t), rtol=1e-9, atol=1e-9)


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
