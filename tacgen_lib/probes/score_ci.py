"""One fixed probe's test score with its bootstrap CI (the resamples of `fixed_test_bootstrap`).

`fixed_test_bootstrap` gives the CI of a difference Delta; the cost-of-accuracy points and the
pretrained-vs-random table also need the CI of one score (the force probe's R^2, a backbone's
accuracy). A probes module: the features stage's table reads it, and the cost stage.
"""

from __future__ import annotations

import numpy as np

from tacgen_lib.probes.bootstrap import resample_indices, score_resamples
from tacgen_lib.probes.metrics import Metric, check_metric, score

__all__ = ["score_ci"]


def score_ci(
    metric: Metric,
    y_true: np.ndarray,
    pred: np.ndarray,
    *,
    n_resamples: int,
    seed: int,
    confidence_level: float = 0.95,
) -> tuple[float, float, float]:
    """Test score of one fixed probe and its percentile bootstrap CI: (score, low, high).

    The test rows are resampled with `resample_indices(n, n_resamples, seed)`, the draw
    `fixed_test_bootstrap` makes with the same seed, so this CI and a Delta CI of the same seed
    see the same resamples. R^2 of a constant resample follows `score_resamples`' rule.
    """
    check_metric(metric)
    y, p = np.asarray(y_true), np.asarray(pred)
    if y.ndim != 1 or p.shape != y.shape:
        raise ValueError(f"score_ci: y_true {y.shape} and pred {p.shape} must be equal 1-D shapes")
    if not 0.0 < confidence_level < 1.0:
        raise ValueError(f"score_ci: confidence_level must be in (0, 1), got {confidence_level}")
    idx = resample_indices(y.size, n_resamples, seed)
    (scores,), _ = score_resamples(metric, y, [p], idx)
    alpha = (1.0 - confidence_level) / 2.0
    lo, hi = np.quantile(scores, [alpha, 1.0 - alpha])
    return float(score(metric, y, p)), float(lo), float(hi)
