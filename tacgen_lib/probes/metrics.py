"""The probe metrics: R^2 (mass, force) and accuracy (density, hardness).

Both equal scikit-learn's (``r2_score``, ``accuracy_score``); `score` picks one by name,
`score_rows` scores every row of a (B, m) prediction matrix (the controls' refits).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

__all__ = ["Metric", "accuracy", "check_metric", "r2", "score", "score_rows"]

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
