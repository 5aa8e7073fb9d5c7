"""The probe metrics: R^2 (mass, force), accuracy (density, hardness) and balanced accuracy
(the transfer probe's mass-quantile classes).

Each equals scikit-learn's (``r2_score``, ``accuracy_score``, ``balanced_accuracy_score``);
`score` picks R^2 or accuracy by name, `score_rows` scores every row of a (B, m) prediction
matrix (the controls' refits), `balanced_accuracy_resamples` scores object-level bootstrap
resamples given as draw counts.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

__all__ = [
    "Metric",
    "accuracy",
    "balanced_accuracy",
    "balanced_accuracy_resamples",
    "check_metric",
    "r2",
    "score",
    "score_rows",
]

Metric = Literal["r2", "accuracy"]


def r2(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """Coefficient of determination, equal to ``sklearn.metrics.r2_score``.

    A constant target (SS_tot = 0) follows scikit-learn's ``force_finite`` rule: 1.0 when the
    predictions are perfect, else 0.0. Constancy is tested exactly (min == max), so a constant
    target whose mean rounds is still recognised.
    """
    y = np.asarray(y_true, dtype=np.float64)
    p = np.asarray(y_pred, dtype=np.float64)
    if y.shape != p.shape or y.ndim != 1:
        raise ValueError(f"r2: y_true {y.shape} and y_pred {p.shape} must be equal 1-D shapes")
    ss_res = float(np.sum((y - p) ** 2))
    if y.min() == y.max():
        return 1.0 if ss_res == 0.0 else 0.0
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return 1.0 - ss_res / ss_tot


def accuracy(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """Fraction of correct labels, equal to ``sklearn.metrics.accuracy_score``."""
    y = np.asarray(y_true)
    p = np.asarray(y_pred)
    if y.shape != p.shape or y.ndim != 1:
        raise ValueError(f"accuracy: y_true {y.shape} and y_pred {p.shape} must be equal 1-D")
    return float(np.mean(y == p))


def balanced_accuracy(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """Mean over the classes present in y_true of each class's recall, equal to
    ``sklearn.metrics.balanced_accuracy_score`` (unadjusted): a probe that always answers
    the majority class scores 1 / n_classes however unbalanced the rows are."""
    y = np.asarray(y_true)
    p = np.asarray(y_pred)
    if y.shape != p.shape or y.ndim != 1 or y.size == 0:
        raise ValueError(
            f"balanced_accuracy: y_true {y.shape} and y_pred {p.shape} must be equal, "
            "non-empty 1-D shapes"
        )
    return float(np.mean([np.mean(p[y == c] == c) for c in np.unique(y)]))


def balanced_accuracy_resamples(
    y_true: np.ndarray, y_pred: np.ndarray, groups: np.ndarray, counts: np.ndarray
) -> np.ndarray:
    """Balanced accuracy of each cluster-bootstrap resample: (B,) float64.

    Rows belong to groups (objects) 0..G-1 (`groups`, (n,) ints); resample b draws group g
    counts[b, g] times (counts (B, G), e.g. `bootstrap.resample_counts` of object indices),
    with all of its rows. A class drawn in no row of a resample is left out of that
    resample's mean, as scikit-learn leaves out classes absent from y_true. Equal to
    `balanced_accuracy` on the rows of each resample listed out.
    """
    y = np.asarray(y_true)
    p = np.asarray(y_pred)
    g = np.asarray(groups, dtype=np.int64)
    counts = np.asarray(counts, dtype=np.float64)
    if not (y.shape == p.shape == g.shape) or y.ndim != 1:
        raise ValueError("balanced_accuracy_resamples: y_true, y_pred, groups must be equal 1-D")
    n_groups = counts.shape[1]
    if g.size and (g.min() < 0 or g.max() >= n_groups):
        raise ValueError(f"balanced_accuracy_resamples: groups must lie in [0, {n_groups})")
    recalls = []
    for c in np.unique(y):
        in_class = y == c
        rows = np.bincount(g[in_class], minlength=n_groups).astype(np.float64)
        hits = np.bincount(g[in_class & (p == c)], minlength=n_groups).astype(np.float64)
        drawn = counts @ rows
        with np.errstate(invalid="ignore", divide="ignore"):
            recalls.append(np.where(drawn > 0, (counts @ hits) / drawn, np.nan))
    recall = np.vstack(recalls)
    present = np.isfinite(recall)
    return np.where(present, recall, 0.0).sum(axis=0) / present.sum(axis=0)


def check_metric(metric: str) -> None:
    if metric not in ("r2", "accuracy"):
        raise ValueError(f"metric must be 'r2' (mass, force) or 'accuracy', got {metric!r}")


def score(metric: Metric, y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """The probe metric on one set of rows: `r2` or `accuracy`."""
    check_metric(metric)
    return r2(y_true, y_pred) if metric == "r2" else accuracy(y_true, y_pred)


def score_rows(metric: Metric, y_true: np.ndarray, preds: np.ndarray) -> np.ndarray:
    """`score` of every row of preds (B, m) against y_true (m,): (B,) float64."""
    return np.array([score(metric, y_true, p) for p in preds], dtype=np.float64)
