"""The paper's CI on the probe gain Delta = score(V+T) - score(V): the fixed-test bootstrap.

This module owns `fixed_test_bootstrap`: the probes are FIXED and the TEST rows resampled
with replacement (optionally within strata such as shape x density x scale cells). Vectorised
over one (n_resamples, n_test) index matrix (`resample_indices`, scored through the count
matrix of `resample_counts`); percentile CI; ``p_gt0`` = fraction of resamples with
Delta > 0.

R^2 of a resample whose target is constant (SS_tot = 0) is defined as in scikit-learn's
``r2_score(force_finite=True)``: 1.0 if the predictions are exact, else 0.0. Such a resample
carries no information about variance explained, and this rule keeps every resample finite
(no NaN can enter a CI) while matching the library reference; it pulls Delta towards 0, i.e.
it is conservative. Constancy is decided exactly from the resample's values (not from a
rounded SS_tot); the number of such resamples is reported as ``n_constant_resamples``.
Accuracy of a single-class resample needs no rule.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tacgen_lib.probes.metrics import Metric, check_metric, score

__all__ = [
    "fixed_test_bootstrap",
    "percentile_interval",
    "resample_counts",
    "resample_indices",
    "score_interval",
    "score_resamples",
]

_CHUNK = 1024  # resamples per vectorised block (bounds memory at ~CHUNK * n floats)


def resample_indices(
    n: int, n_resamples: int, seed: int, *, strata: np.ndarray | None = None
) -> np.ndarray:
    """(n_resamples, n) bootstrap index matrix drawn with ``numpy.random.default_rng(seed)``.

    Unstratified, the draw is ``rng.integers(0, n, (n_resamples, n))`` -- the same call as
    ``scipy.stats.bootstrap``, so both see identical resamples for the same Generator state.
    With strata (one label per row), column j is redrawn from the rows of j's stratum, so
    every resample keeps the stratum sizes; strata are visited in sorted order.
    """
    if n < 1 or n_resamples < 1:
        raise ValueError(
            f"resample_indices: need n >= 1 and n_resamples >= 1, got {n}, {n_resamples}"
        )
    rng = np.random.default_rng(seed)
    if strata is None:
        return rng.integers(0, n, (n_resamples, n))
    strata = np.asarray(strata)
    if strata.shape != (n,):
        raise ValueError(f"strata: expected one label per test row ({n}), got {strata.shape}")
    idx = np.empty((n_resamples, n), dtype=np.int64)
    for s in np.unique(strata):
        rows = np.flatnonzero(strata == s)
        idx[:, rows] = rows[rng.integers(0, rows.size, (n_resamples, rows.size))]
    return idx


def resample_counts(idx: np.ndarray, n: int) -> np.ndarray:
    """(B, n) float64 matrix: how often each row appears in each resample of idx (B, m)."""
    b = idx.shape[0]
    flat = (idx + n * np.arange(b)[:, None]).ravel()
    return np.bincount(flat, minlength=b * n).reshape(b, n).astype(np.float64)


def score_resamples(
    metric: Metric, y_true: np.ndarray, preds: Sequence[np.ndarray], idx: np.ndarray
) -> tuple[list[np.ndarray], np.ndarray]:
    """Metric of every prediction vector on each resample (row of idx), vectorised.

    Works through the count matrix W = `resample_counts(idx)`: every per-resample sum is one
    product W @ v, so no (B, n) copy of the data is gathered. For R^2,
    SS_tot = sum w (y - c)^2 - m (sum w (y - c) / m)^2 with c the full-sample mean (the
    shift keeps the difference well conditioned: bootstrap means sit near c). Resamples whose
    SS_tot is at rounding level are re-examined exactly from their indices: constant ones get
    the documented R^2 rule, the rest an exactly computed SS_tot.
    Returns ([scores (B,) per prediction], constant_target (B,)).
    """
    check_metric(metric)
    y = np.asarray(y_true)
    m = idx.shape[1]
    const = np.zeros(idx.shape[0], dtype=bool)
    if metric == "accuracy":
        cols = np.column_stack([(y == np.asarray(p)).astype(np.float64) for p in preds])
        out = np.empty((idx.shape[0], len(preds)))
        for a in range(0, idx.shape[0], _CHUNK):
            out[a : a + _CHUNK] = resample_counts(idx[a : a + _CHUNK], y.size) @ cols / m
        return [out[:, k] for k in range(len(preds))], const
    y = y.astype(np.float64)
    yc = y - y.mean()
    cols = np.column_stack([yc, yc**2] + [(y - np.asarray(p, np.float64)) ** 2 for p in preds])
    sums = np.empty((idx.shape[0], cols.shape[1]))
    for a in range(0, idx.shape[0], _CHUNK):
        sums[a : a + _CHUNK] = resample_counts(idx[a : a + _CHUNK], y.size) @ cols
    ss_tot = sums[:, 1] - sums[:, 0] ** 2 / m
    suspect = np.flatnonzero(ss_tot <= 1e3 * m * np.finfo(np.float64).eps * sums[:, 1])
    for b in suspect:  # rare: near-constant resamples, decided exactly
        yb = y[idx[b]]
        const[b] = bool(np.all(yb == yb[0]))
        ss_tot[b] = np.sum((yb - yb.mean()) ** 2)
    scores = []
    for k in range(len(preds)):
        ss_res = sums[:, 2 + k]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = 1.0 - ss_res / ss_tot
        scores.append(np.where(const, np.where(ss_res == 0.0, 1.0, 0.0), r))
    return scores, const


def percentile_interval(
    values: np.ndarray, *, confidence_level: float = 0.95
) -> tuple[float, float]:
    """The central ``confidence_level`` percentile interval of bootstrap `values` (linear
    interpolation, as ``numpy.quantile``): every CI of this module."""
    if not 0.0 < confidence_level < 1.0:
        raise ValueError(f"confidence_level must be in (0, 1), got {confidence_level}")
    alpha = (1.0 - confidence_level) / 2.0
    lo, hi = np.quantile(values, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


def score_interval(
    metric: Metric,
    y_true: np.ndarray,
    pred: np.ndarray,
    indices: np.ndarray,
    *,
    confidence_level: float = 0.95,
) -> tuple[float, float]:
    """Percentile interval of one probe's test score over the fixed-test resamples
    `indices` (B, n) (the probe held fixed, as in `fixed_test_bootstrap`)."""
    (scores,), _ = score_resamples(metric, np.asarray(y_true), [np.asarray(pred)], indices)
    return percentile_interval(scores, confidence_level=confidence_level)


def fixed_test_bootstrap(
    y_true: np.ndarray,
    pred_v: np.ndarray,
    pred_vt: np.ndarray,
    metric: Metric,
    n_resamples: int,
    seed: int,
    strata: np.ndarray | None = None,
    *,
    confidence_level: float = 0.95,
    indices: np.ndarray | None = None,
    return_distribution: bool = False,
    sample_ids: Sequence | np.ndarray | None = None,
) -> dict:
    """Fixed-probe bootstrap of Delta = metric(V+T) - metric(V) over the TEST rows.

    Both probes' test predictions are held fixed; the same resample of test rows scores
    both, so the CI reflects the paired difference. ``indices`` (B, n) overrides the drawn
    resamples (used to compare with other implementations on identical resamples).
    Returns v_score, vt_score, delta (full test set), ci_low, ci_high (percentile CI, linear
    interpolation as ``numpy.quantile``), p_gt0, n_resamples, n_constant_resamples.
    """
    check_metric(metric)
    y = np.asarray(y_true)
    pv = np.asarray(pred_v)
    pvt = np.asarray(pred_vt)
    if not (y.ndim == 1 and pv.shape == y.shape and pvt.shape == y.shape):
        raise ValueError(
            f"fixed_test_bootstrap: y_true {y.shape}, pred_v {pv.shape} and pred_vt "
            f"{pvt.shape} must be equal 1-D shapes (one value per test row)"
        )
    if metric == "r2":
        for name, a in (("y_true", y), ("pred_v", pv), ("pred_vt", pvt)):
            bad = ~np.isfinite(np.asarray(a, dtype=np.float64))
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                where = f"sample_id {sample_ids[i]!r}" if sample_ids is not None else f"row {i}"
                raise ValueError(
                    f"fixed_test_bootstrap: {name} is non-finite at test {where}; "
                    "check the probe's inputs for that sample"
                )
    if not 0.0 < confidence_level < 1.0:
        raise ValueError(f"confidence_level must be in (0, 1), got {confidence_level}")
    if indices is None:
        idx = resample_indices(y.size, n_resamples, seed, strata=strata)
    else:
        idx = np.asarray(indices)
        if idx.ndim != 2 or idx.shape[1] != y.size:
            raise ValueError(f"indices: expected (B, {y.size}), got {idx.shape}")
    (s_v, s_vt), c_v = score_resamples(metric, y, [pv, pvt], idx)
    deltas = s_vt - s_v
    lo, hi = percentile_interval(deltas, confidence_level=confidence_level)
    v_score = score(metric, y, pv)
    vt_score = score(metric, y, pvt)
    out = {
        "v_score": v_score,
        "vt_score": vt_score,
        "delta": vt_score - v_score,
        "ci_low": float(lo),
        "ci_high": float(hi),
        "p_gt0": float(np.mean(deltas > 0.0)),
        "n_resamples": int(idx.shape[0]),
        "n_constant_resamples": int(c_v.sum()),
        "confidence_level": confidence_level,
    }
    if return_distribution:
        out["deltas"] = deltas
    return out
