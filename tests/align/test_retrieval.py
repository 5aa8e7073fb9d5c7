"""Tests of tacgen_lib.align.retrieval against a plain-loop reference (math.fsum dot products)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tacgen_lib.align.retrieval import TIE_RTOL, paired_retrieval


def reference_ranks(q: np.ndarray, c: np.ndarray) -> list[int]:
    """Rank of the positive per query with plain loops; ties count against the positive."""
    n = len(q)
    c_max = max(math.sqrt(math.fsum(x * x for x in row)) for row in c.tolist())
    ranks = []
    for i in range(n):
        qi = q[i].tolist()
        q_norm = math.sqrt(math.fsum(x * x for x in qi))
        sims = [math.fsum(a * b for a, b in zip(qi, c[j].tolist(), strict=True)) for j in range(n)]
        tol = TIE_RTOL * q_norm * c_max
        rank = 1
        for j in range(n):
            if j != i and sims[j] >= sims[i] - tol:
                rank += 1
        ranks.append(rank)
    return ranks


def reference_metrics(z_v: np.ndarray, z_t: np.ndarray) -> dict[str, float]:
    r1, r2 = reference_ranks(z_v, z_t), reference_ranks(z_t, z_v)
    n = len(r1)

    def median(r):
        s = sorted(r)
        return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])

    return {
        "top1_v2t": sum(r <= 1 for r in r1) / n,
        "top1_t2v": sum(r <= 1 for r in r2) / n,
        "top5_v2t": sum(r <= 5 for r in r1) / n,
        "top5_t2v": sum(r <= 5 for r in r2) / n,
        "median_rank_v2t": float(median(r1)),
        "median_rank_t2v": float(median(r2)),
        "chance_top1": 1 / n,
        "chance_top5": min(5, n) / n,
        "n": n,
    }


def test_perfect_alignment_is_rank_one():
    z = np.eye(6, dtype=np.float32)
    m = paired_retrieval(z, z)
    assert m["top1_v2t"] == m["top1_t2v"] == 1.0
    assert m["median_rank_v2t"] == m["median_rank_t2v"] == 1.0
    assert m["chance_top1"] == pytest.approx(1 / 6) and m["chance_top5"] == pytest.approx(5 / 6)


def test_known_ranks_and_directions_differ():
    z_v = np.eye(4)
    z_t = np.array([[1.0, 0, 0, 0], [0.9, 0.1, 0, 0], [0.9, 0, 0.2, 0], [0, 0, 0, 1.0]])
    m = paired_retrieval(z_v, z_t)
    # sim[i, j] = v_i . t_j = z_t[j, i]. v2t (rows of sim): v_1 sees t_j[1] = (0, .1, 0, 0),
    # its positive is the largest; likewise every v_i: all rank 1.
    assert m["top1_v2t"] == 1.0 and m["median_rank_v2t"] == 1.0
    # t2v (columns): t_1 sees v_j . t_1 = (.9, .1, 0, 0) -> rank 2; t_2 sees (.9, 0, .2, 0) ->
    # rank 2; t_0 and t_3 rank 1. So top-1 0.5, median rank 1.5, top-5 1.
    assert m["top1_t2v"] == 0.5 and m["median_rank_t2v"] == 1.5 and m["top5_t2v"] == 1.0
    assert m == reference_metrics(z_v, z_t)


def test_all_identical_rows_are_worst_rank():
    z = np.tile(np.array([[0.3, -0.2, 0.9]], dtype=np.float32), (7, 1))
    m = paired_retrieval(z, z)
    assert m["top1_v2t"] == m["top1_t2v"] == 0.0
    assert m["median_rank_v2t"] == m["median_rank_t2v"] == 7.0
    assert m == reference_metrics(z.astype(np.float64), z.astype(np.float64))


def test_zero_vectors_tie_everything():
    z = np.zeros((5, 4))
    m = paired_retrieval(z, z)
    assert m["top1_v2t"] == 0.0 and m["median_rank_t2v"] == 5.0


def test_single_pair():
    m = paired_retrieval(np.ones((1, 3)), np.ones((1, 3)))
    assert m["top1_v2t"] == 1.0 and m["n"] == 1 and m["chance_top5"] == 1.0


def test_chunked_matches_reference_beyond_one_chunk(monkeypatch):
    import tacgen_lib.align.retrieval as retrieval

    monkeypatch.setattr(retrieval, "_CHUNK", 7)  # force several chunks on a small problem
    rng = np.random.default_rng(0)
    z_v = rng.standard_normal((30, 5)).astype(np.float32)
    z_t = (z_v + 0.8 * rng.standard_normal((30, 5))).astype(np.float32)
    z_t[3] = z_t[4]  # an exact duplicate candidate
    assert retrieval.paired_retrieval(z_v, z_t) == reference_metrics(
        z_v.astype(np.float64), z_t.astype(np.float64)
    )


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 12),
    d=st.integers(1, 6),
    seed=st.integers(0, 2**16),
    quantise=st.booleans(),
)
def test_property_matches_plain_loop_reference(n, d, seed, quantise):
    rng = np.random.default_rng(seed)
    z_v = rng.standard_normal((n, d))
    z_t = rng.standard_normal((n, d))
    if quantise:  # coarse values make exact ties frequent
        z_v, z_t = np.round(z_v), np.round(z_t)
    assert paired_retrieval(z_v, z_t) == reference_metrics(z_v, z_t)


@pytest.mark.parametrize(
    "a, b, match",
    [
        (np.zeros((3, 2)), np.zeros((4, 2)), "same shape"),
        (np.zeros((0, 2)), np.zeros((0, 2)), "non-empty"),
        (np.array([[1.0, np.nan]]), np.ones((1, 2)), "row 0"),
    ],
)
def test_rejects_bad_input(a, b, match):
    with pytest.raises(ValueError, match=match):
        paired_retrieval(a, b)
