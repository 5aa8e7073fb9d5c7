"""Paired cross-modal retrieval metrics: top-k accuracy and median rank, both directions.

This module owns `paired_retrieval`, the evaluation of aligned projections: row i of z_v and
row i of z_t are the same sample (a positive pair); every other row of the other modality is a
candidate. Similarity is the dot product (cosine for l2-normalised projections), computed in
float64 in row chunks, vectorised with numpy.

Rank convention: rank 1 means the positive is retrieved first. Ties are resolved
deterministically and conservatively: every other candidate whose similarity is greater than
*or equal to* the positive's (within a tie tolerance of ``TIE_RTOL * |q| * max|c|``, which
absorbs float64 summation-order noise) is ranked ahead of the positive. So N identical rows
give every query rank N, never a lucky rank 1.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TIE_RTOL", "paired_retrieval", "retrieval_ranks"]

TIE_RTOL = 1e-10
_CHUNK = 1024


def _as_matrix(x: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(x)
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(
            f"paired_retrieval: {name} must be a non-empty (N, d) array, got {arr.shape}"
        )
    arr = arr.astype(np.float64, copy=False)
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        raise ValueError(
            f"paired_retrieval: {name} row {int(bad[0])} has non-finite values "
            f"({bad.size} such rows); the projections upstream are broken"
        )
    return arr


def retrieval_ranks(queries: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """Rank (1-based, ties counted against) of candidate i for query i, for every i.

    ``rank_i = 1 + #{j != i : q_i . c_j >= q_i . c_i - TIE_RTOL * |q_i| * max_j |c_j|}``.
    """
    q = _as_matrix(queries, "queries")
    c = _as_matrix(candidates, "candidates")
    if q.shape != c.shape:
        raise ValueError(
            f"paired_retrieval: paired matrices must have the same shape, got {q.shape} and "
            f"{c.shape} (row i of each must be the same sample; project both to the same dim)"
        )
    n = q.shape[0]
    c_max = float(np.sqrt((c * c).sum(axis=1)).max())
    q_norm = np.sqrt((q * q).sum(axis=1))
    ranks = np.empty(n, dtype=np.int64)
    for lo in range(0, n, _CHUNK):
        hi = min(n, lo + _CHUNK)
        sim = q[lo:hi] @ c.T  # (chunk, n)
        rows = np.arange(hi - lo)
        pos = sim[rows, lo + rows]
        tol = TIE_RTOL * q_norm[lo:hi] * c_max
        ahead = sim >= (pos - tol)[:, None]
        ranks[lo:hi] = ahead.sum(axis=1)  # counts the positive itself, hence already 1-based
    return ranks


RETRIEVAL_METRICS = (
    "top1_v2t",
    "top1_t2v",
    "top5_v2t",
    "top5_t2v",
    "median_rank_v2t",
    "median_rank_t2v",
)
"""The retrieval metrics of `paired_retrieval` (besides chance levels and n), in table order."""
CHANCE_COLUMNS = ("chance_top1", "chance_top5")


def paired_retrieval(z_v: np.ndarray, z_t: np.ndarray) -> dict[str, float]:
    """Cross-modal retrieval of paired projections (vision->touch and touch->vision).

    z_v, z_t: (N, d) projections; row i of each is a positive pair.
    Returns top1_v2t, top1_t2v, top5_v2t, top5_t2v (fraction of queries whose positive has rank
    <= k), median_rank_v2t, median_rank_t2v (1 = first), chance_top1 = 1/N,
    chance_top5 = min(5, N)/N and n = N. Ties count against the positive (module docstring).
    """
    r_v2t = retrieval_ranks(z_v, z_t)
    r_t2v = retrieval_ranks(z_t, z_v)
    n = int(r_v2t.size)
    return {
        "top1_v2t": float(np.mean(r_v2t <= 1)),
        "top1_t2v": float(np.mean(r_t2v <= 1)),
        "top5_v2t": float(np.mean(r_v2t <= 5)),
        "top5_t2v": float(np.mean(r_t2v <= 5)),
        "median_rank_v2t": float(np.median(r_v2t)),
        "median_rank_t2v": float(np.median(r_t2v)),
        "chance_top1": 1.0 / n,
        "chance_top5": min(5, n) / n,
        "n": n,
    }
