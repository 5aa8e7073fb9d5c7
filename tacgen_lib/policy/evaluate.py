"""Evaluation of the policy stage: success with bootstrap CIs, the paired Δsuccess CI,
failure modes, the capacity sweep's closed gap, and the palpation grip-force regression."""

from __future__ import annotations

import numpy as np

from tacgen_lib.policy.task import FAILURE_MODES

__all__ = [
    "success_ci",
    "paired_delta_ci",
    "failure_counts",
    "gap_closed",
    "grip_force_regression",
]


def _indices(n: int, n_resamples: int, seed: int) -> np.ndarray:
    return np.random.default_rng([seed, 0xB007]).integers(0, n, size=(n_resamples, n))


def success_ci(success: np.ndarray, n_resamples: int, seed: int) -> tuple[float, float, float]:
    """Success rate and its 95 % percentile bootstrap CI over episodes."""
    s = np.asarray(success, dtype=np.float64)
    boot = s[_indices(len(s), n_resamples, seed)].mean(1)
    return float(s.mean()), float(np.quantile(boot, 0.025)), float(np.quantile(boot, 0.975))


def paired_delta_ci(
    success: np.ndarray, reference: np.ndarray, n_resamples: int, seed: int
) -> tuple[float, float, float]:
    """Δsuccess = mean(success - reference) on the same episodes, with a **paired** bootstrap:
    each resample draws episodes once and scores both conditions on them."""
    a = np.asarray(success, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"paired_delta_ci: {a.shape} vs {b.shape}: not the same episodes")
    d = a - b
    boot = d[_indices(len(d), n_resamples, seed)].mean(1)
    return float(d.mean()), float(np.quantile(boot, 0.025)), float(np.quantile(boot, 0.975))


def failure_counts(modes: np.ndarray) -> dict[str, int]:
    """Episodes per outcome (success, slip, crush, drop, miss)."""
    modes = np.asarray(modes)
    bad = sorted(set(modes) - set(FAILURE_MODES))
    if bad:
        raise ValueError(f"failure_counts: unknown outcome {bad[0]!r}")
    return {m: int((modes == m).sum()) for m in FAILURE_MODES}


def gap_closed(best_v: float, v: float, vt: float) -> float:
    """Fraction of the V -> V+T gap that the best V-only sweep cell closes (nan if no gap)."""
    gap = vt - v
    return float((best_v - v) / gap) if gap > 0 else float("nan")


def grip_force_regression(
    x_v: np.ndarray,
    x_vt: np.ndarray,
    y: np.ndarray,
    train: np.ndarray,
    n_resamples: int,
    seed: int,
) -> dict[str, float]:
    """Ridge probes (λ by 5-fold CV on the training rows) V vs V+T -> y; R² on the held-out rows
    and ΔR² with a fixed-test bootstrap CI (both probes' test predictions fixed, the same
    resample scores both)."""
    from sklearn.linear_model import RidgeCV  # here: the policy summary's readers skip it

    alphas = np.logspace(-2, 4, 13)
    test = ~train
    preds = []
    for x in (x_v, x_vt):
        mean, sd = x[train].mean(0), x[train].std(0) + 1e-6
        z = (x - mean) / sd
        model = RidgeCV(alphas=alphas, cv=5).fit(z[train], y[train])
        preds.append(model.predict(z[test]))
    yt = y[test]

    def r2(idx: np.ndarray, p: np.ndarray) -> np.ndarray:
        yy, pp = yt[idx], p[idx]
        ss_tot = ((yy - yy.mean(axis=-1, keepdims=True)) ** 2).sum(-1)
        return 1.0 - ((yy - pp) ** 2).sum(-1) / np.maximum(ss_tot, 1e-12)

    full = np.arange(len(yt))
    idx = _indices(len(yt), n_resamples, seed)
    delta = r2(idx, preds[1]) - r2(idx, preds[0])
    r_v, r_vt = float(r2(full, preds[0])), float(r2(full, preds[1]))
    return {
        "r2_v": r_v,
        "r2_vt": r_vt,
        "delta_r2": r_vt - r_v,
        "ci_low": float(np.quantile(delta, 0.025)),
        "ci_high": float(np.quantile(delta, 0.975)),
        "n_train": int(train.sum()),
        "n_test": int(test.sum()),
    }
