"""The simplest V->T generator, judged beside the diffusion generator: multi-output ridge
regression of the tactile features on the visual ones.

Two arms come from one fit on the generator's own train rows (the alignment-train split the
diffusion generator learns from):

- ``t_ridge``: the conditional mean E[T | V] of a linear model. Any generator that predicts T
  from V must at least match it on matched-pair fidelity, or it has learned less of the map
  than a closed-form regression;
- ``t_ridge_residual``: that mean plus a residual drawn (seeded) from the train residuals, a
  sample with roughly the real spread around the mean, the simplest *stochastic* generator.
  The residuals are in-sample, so the spread is slightly under-stated.

The ridge penalty is chosen among `RIDGE_ALPHAS` by scikit-learn's efficient leave-one-out
(generalised cross-validation) on the train rows, one penalty for all outputs; no val or test
row is read. Everything is float64.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.linear_model import RidgeCV

#: The ridge penalties leave-one-out chooses from (13 steps from 1e-3 to 1e3 in log space).
RIDGE_ALPHAS: tuple[float, ...] = tuple(float(a) for a in np.logspace(-3, 3, 13))


@dataclass(frozen=True)
class RidgeGeneration:
    """One ridge V->T generator's output for every row of a corpus.

    ``mean`` / ``residual``: sample_id -> generated tactile vector (float64) of the two arms;
    ``alpha``: the penalty leave-one-out chose; ``n_train``: the rows it was fitted on.
    """

    mean: Mapping[str, np.ndarray]
    residual: Mapping[str, np.ndarray]
    alpha: float
    n_train: int


def ridge_generate(
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    train_ids: Sequence[str],
    *,
    seed: int,
    alphas: Sequence[float] = RIDGE_ALPHAS,
) -> RidgeGeneration:
    """Fit ridge T ~ V on `train_ids` and generate both arms for every sample_id of `vision`.

    The residual arm adds, to row i's mean, the train residual of a train row drawn with a
    generator seeded by `seed` (rows drawn in sorted sample_id order, so the draw does not
    depend on the mapping's order). Needs at least 2 train rows (leave-one-out).
    """
    train_ids = sorted(str(i) for i in train_ids)
    if len(train_ids) < 2:
        raise ValueError(f"ridge_generate: need at least 2 train rows, got {len(train_ids)}")
    missing = [i for i in train_ids if i not in vision or i not in t_real]
    if missing:
        raise ValueError(
            f"ridge_generate: train row {missing[0]!r} has no vision or tactile vector "
            f"({len(missing)} such rows)"
        )
    v_tr = np.stack([np.asarray(vision[i], np.float64) for i in train_ids])
    t_tr = np.stack([np.asarray(t_real[i], np.float64) for i in train_ids])
    model = RidgeCV(alphas=list(alphas), fit_intercept=True).fit(v_tr, t_tr)
    residuals = t_tr - model.predict(v_tr)
    ids = sorted(vision)
    mean = model.predict(np.stack([np.asarray(vision[i], np.float64) for i in ids]))
    draw = np.random.default_rng(seed).integers(0, len(train_ids), size=len(ids))
    sampled = mean + residuals[draw]
    return RidgeGeneration(
        mean=dict(zip(ids, mean, strict=True)),
        residual=dict(zip(ids, sampled, strict=True)),
        alpha=float(model.alpha_),
        n_train=len(train_ids),
    )
