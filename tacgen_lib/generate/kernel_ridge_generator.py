"""The ladder's nonlinear regression rung (`generate.ladder`, between ``ridge`` and
``gen_mean``): multi-output RBF kernel ridge regression of the tactile features T on the visual
ones V, learnt from the unlabelled paired pool only.

What it asks of the ladder: where ``ridge`` (a linear map from V) loses the gain and this rung
keeps it, a nonlinear regression carries what V predicts of T and the diffusion generator's
mean should too; where this rung loses it as well, no smooth function of V learnt from the pool
carries it.

The fit, on the pool's rows (never a labelled or a test row: `kernel_ridge_generate` refuses a
row asked for that is in the pool):

- V is standardised by the pool's mean and sd (scikit-learn's StandardScaler, refitted inside
  each CV fold, as the ``knn`` rung), T centred by the pool's mean (the kernel has no intercept);
- gamma = multiple / `generate.baselines.median_sq_distance` of the pool's standardised V, the
  multiple among config ``regime.kernel_ridge_gammas``, and the penalty lambda among
  ``regime.kernel_ridge_lambdas``, both chosen by `KERNEL_RIDGE_FOLDS`-fold CV (seeded shuffle)
  of the T prediction on the pool, scored by the mean over T's dimensions of the held-out R²
  (each dimension weighs the same, whatever its variance);
- a pool of at most ``regime.nystroem_above`` rows: exact kernel ridge (scikit-learn's
  KernelRidge); a larger pool: ridge on ``regime.nystroem_rank`` Nystroem features (scikit-learn's
  Nystroem, landmark rows drawn with the seed), the same lambda meaning the same penalty (ridge
  on the Nystroem map is kernel ridge with the low-rank kernel), so the grid serves both.

Everything is float64.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tacgen_lib.generate.baselines import median_sq_distance, nystroem_ridge, standardise
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.regime_sets import RegimeSettings

if TYPE_CHECKING:
    from sklearn.compose import TransformedTargetRegressor

__all__ = [
    "KERNEL_RIDGE_FOLDS",
    "KernelRidgeGeneration",
    "kernel_ridge_generate",
    "kernel_ridge_model",
]

#: The CV folds the kernel ridge rung chooses gamma and lambda by.
KERNEL_RIDGE_FOLDS = 5


@dataclass(frozen=True)
class KernelRidgeGeneration:
    """The kernel ridge rung's T_gen (sample_id -> float64 vector) for the rows asked for;
    the gamma multiple and the lambda CV chose, gamma itself, the CV's mean R² over T's
    dimensions (NaN without CV), and the Nystroem rank (0: the exact kernel)."""

    t_gen: dict[str, np.ndarray]
    gamma_multiple: float
    gamma: float
    lam: float
    cv_r2: float
    nystroem_rank: int

    def describe(self) -> str:
        """The fit in words: gamma multiple, lambda, exact or Nystroem with its rank."""
        how = "exact kernel" if self.nystroem_rank == 0 else f"Nystroem rank {self.nystroem_rank}"
        return f"gamma = {self.gamma_multiple:g} x median heuristic, lambda = {self.lam:g}, {how}"


def kernel_ridge_model(
    gamma: float, lam: float, *, nystroem_rank: int, seed: int
) -> TransformedTargetRegressor:
    """The unfitted model of one (gamma, lambda): StandardScaler on V then exact RBF kernel
    ridge (``nystroem_rank`` 0) or ridge on that many RBF Nystroem features (landmarks drawn
    with `seed`), T centred by its training mean (scikit-learn's TransformedTargetRegressor)."""
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.kernel_ridge import KernelRidge
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    if int(nystroem_rank) == 0:
        fit = KernelRidge(alpha=float(lam), kernel="rbf", gamma=float(gamma))
    else:
        fit = nystroem_ridge(gamma, lam, rank=int(nystroem_rank), seed=int(seed))
    inner = make_pipeline(StandardScaler(), fit)
    return TransformedTargetRegressor(
        regressor=inner, transformer=StandardScaler(with_std=False), check_inverse=False
    )


def kernel_ridge_generate(
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    pool: Sequence[str],
    rows: Sequence[str],
    *,
    regime: RegimeSettings,
    seed: int,
    n_folds: int = KERNEL_RIDGE_FOLDS,
) -> KernelRidgeGeneration:
    """The kernel ridge rung's T_gen for `rows`, fitted on `pool` (module docstring).

    regime: the grids (``kernel_ridge_gammas``, ``kernel_ridge_lambdas``) and where the
    Nystroem features take over (``nystroem_above``, ``nystroem_rank``). The CV's folds are
    shuffled with `seed`, which also draws the Nystroem landmarks. With fewer than `n_folds`
    pool rows there is no CV: the middle of each grid (the lower middle for an even grid), and
    ``cv_r2`` NaN. A Nystroem rank larger than a CV training fold is capped at it there.

    Raises ValueError when a row asked for is in the pool (the pool is unlabelled and the rows
    a probe reads are labelled or test rows: one in both would fit T_gen on its own touch), on
    a pool of fewer than 2 rows, or on a row without a vector.
    """
    from sklearn.model_selection import KFold

    pool = [str(i) for i in pool]
    rows = [str(i) for i in rows]
    if len(pool) < 2:
        raise ValueError(f"kernel_ridge_generate: the pool needs >= 2 rows, got {len(pool)}")
    shared = sorted(set(pool) & set(rows))
    if shared:
        raise ValueError(
            f"kernel_ridge_generate: row {shared[0]!r} is in the pool ({len(shared)} such): "
            "T_gen of a labelled or test row is learnt from pool rows only"
        )
    what = "kernel_ridge_generate"
    v_pool, t_pool = feature_block(vision, pool, what=what), feature_block(t_real, pool, what=what)
    multiples = [float(g) for g in regime.kernel_ridge_gammas]
    lambdas = [float(v) for v in regime.kernel_ridge_lambdas]
    n = len(pool)
    rank = min(int(regime.nystroem_rank), n) if n > int(regime.nystroem_above) else 0
    med = median_sq_distance(standardise(v_pool, v_pool[:0])[0])
    if n >= n_folds >= 2:
        folds = list(KFold(n_folds, shuffle=True, random_state=int(seed)).split(v_pool))
        best = (-np.inf, multiples[0], lambdas[0])
        for mult in multiples:
            for lam in lambdas:
                cv = float(
                    np.mean(
                        [_fold_r2(v_pool, t_pool, f, mult / med, lam, rank, seed) for f in folds]
                    )
                )
                if cv > best[0]:  # the first of equal scores: the grids' order
                    best = (cv, mult, lam)
        cv_r2, mult, lam = best
        cv_r2 = cv_r2 if np.isfinite(cv_r2) else float("nan")  # no fold scored (constant T)
    else:
        mult = sorted(multiples)[(len(multiples) - 1) // 2]
        lam = sorted(lambdas)[(len(lambdas) - 1) // 2]
        cv_r2 = float("nan")
    model = kernel_ridge_model(mult / med, lam, nystroem_rank=rank, seed=seed)
    pred = model.fit(v_pool, t_pool).predict(feature_block(vision, rows, what=what))
    return KernelRidgeGeneration(
        dict(zip(rows, np.asarray(pred, np.float64), strict=True)),
        gamma_multiple=mult,
        gamma=mult / med,
        lam=lam,
        cv_r2=cv_r2,
        nystroem_rank=rank,
    )


def _fold_r2(
    v: np.ndarray,
    t: np.ndarray,
    fold: tuple[np.ndarray, np.ndarray],
    gamma: float,
    lam: float,
    rank: int,
    seed: int,
) -> float:
    """The held-out R² of one CV fold, averaged over T's dimensions (scikit-learn's r2_score,
    uniform average)."""
    from sklearn.metrics import r2_score

    train, held = fold
    model = kernel_ridge_model(gamma, lam, nystroem_rank=min(rank, len(train)), seed=seed)
    pred = model.fit(v[train], t[train]).predict(v[held])
    return float(r2_score(t[held], pred, multioutput="uniform_average"))
