"""The regime's ladder of generators: from an oracle that sees the look to one diffusion sample.

Every rung maps a row to generated touch T_gen using only the unlabelled paired pool (its V,
its real T and, for the oracle, the corpus's own metadata of what each frame shows); the
regime (`tacgen_lib.generate.regime`) scores V + T_gen of each rung with the same probes on the
same test rows. Reading the rungs from the top tells where a gain is lost:

- ``look_oracle`` (A0): the mean real T of the pool rows with the row's look (colour, texture,
  shape, size third; `corpus.looks.look_keys`). What a generator with perfect vision could
  give: the positive control. A look that fewer than ``min_rows`` pool rows share backs off to
  a coarser look (colour, texture, shape; then colour, texture: `corpus.looks.look_levels`),
  and a look no level holds to the pool mean, each counted;
- ``knn`` (A1): the mean real T of the k nearest pool rows in (standardised) V, k chosen by
  K-fold CV of the T prediction on the pool: nonparametric, and only as good as V's
  neighbourhoods;
- ``ridge``: multi-output ridge T ~ V on the pool (`generate.ridge_generator.ridge_generate`), the
  simplest generator;
- ``kernel_ridge``: multi-output RBF kernel ridge T ~ V on the pool, gamma and lambda chosen by
  K-fold CV on the pool, Nystroem features above a pool size
  (`generate.kernel_ridge_generator.kernel_ridge_generate`): a nonlinear regression;
- ``gen_mean`` (A2): the mean of K samples of the diffusion generator (its conditional mean);
- ``v_tgen`` (A3): one sample of it, the paper's arm.

A0 without a gain says the probe or the evaluation is broken; A0 gains and A1 not, V does not
see what the look shows; A1 gains and ridge not, a linear map from V does not carry it; ridge
loses it and kernel ridge keeps it, the map is nonlinear (and the generator should learn it);
the regressions gain and A2 not, the generator loses it; A2 gains and A3 not, sampling noise or
the probe does.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.regime_sets import RegimeSettings

__all__ = [
    "LADDER",
    "KnnGeneration",
    "LadderRungs",
    "LookOracle",
    "knn_generate",
    "ladder_rungs",
    "look_oracle",
]

#: The rungs, top (the oracle) to bottom (today's one-sample arm).
LADDER: tuple[str, ...] = ("look_oracle", "knn", "ridge", "kernel_ridge", "gen_mean", "v_tgen")

#: The CV folds the kNN rung chooses its k by (`knn_generate`).
KNN_FOLDS = 5


@dataclass(frozen=True)
class LookOracle:
    """The look oracle's T_gen (sample_id -> float64 vector) for the rows asked for; how many
    rows took each level of the back-off (``levels[k]``: rows averaged at look level k, the
    last entry the rows given the pool mean), and the distinct finest looks of the pool."""

    t_gen: dict[str, np.ndarray]
    levels: tuple[int, ...]
    n_looks: int

    @property
    def n_fallback(self) -> int:
        """Rows whose look, at every level, is absent from the pool (given the pool mean)."""
        return self.levels[-1]


def look_oracle(
    t_real: Mapping[str, np.ndarray],
    looks: Mapping[str, str] | pd.Series | Sequence[Mapping[str, str] | pd.Series],
    pool: Sequence[str],
    rows: Sequence[str],
    *,
    min_rows: int,
) -> LookOracle:
    """A0: each row's T_gen is the mean real T of the pool rows that share its look.

    looks: sample_id -> look key (`corpus.looks.look_keys`) for every pool row and row, or a
    sequence of such keys from the finest look to coarser ones (`corpus.looks.look_levels`).
    A row takes the finest level whose key at least `min_rows` pool rows share; a row whose
    key no level holds that often gets the mean real T of the whole pool. Counts per level
    are in ``levels``. Float64 sums; with one level and ``min_rows=1`` a look with one pool
    row gives that row's T exactly.
    """
    pool = [str(i) for i in pool]
    rows = [str(i) for i in rows]
    if not pool:
        raise ValueError("look_oracle: the pool is empty")
    if int(min_rows) < 1:
        raise ValueError(f"look_oracle: min_rows must be >= 1, got {min_rows}")
    single = isinstance(looks, (Mapping, pd.Series))
    levels = [pd.Series(k).astype(str) for k in ([looks] if single else looks)]
    for look in levels:
        missing = [i for i in (*pool, *rows) if i not in look.index]
        if missing:
            raise ValueError(f"look_oracle: sample_id {missing[0]!r} has no look")
    t_pool = feature_block(t_real, pool, what="look_oracle")
    frame = pd.DataFrame(t_pool)
    tables = []
    for look in levels:
        keys = look.loc[pool].to_numpy()
        groups = frame.groupby(keys, sort=True)
        means, sizes = groups.mean(), groups.size()
        tables.append(
            {k: means.loc[k].to_numpy(np.float64) for k in means.index if sizes[k] >= min_rows}
        )
    fallback = t_pool.mean(axis=0)
    out, counts = {}, [0] * (len(levels) + 1)
    for i in rows:
        for k, (look, table) in enumerate(zip(levels, tables, strict=True)):
            vec = table.get(look.loc[i])
            if vec is not None:
                out[i], counts[k] = vec, counts[k] + 1
                break
        else:
            out[i], counts[-1] = fallback, counts[-1] + 1
    return LookOracle(out, tuple(counts), int(levels[0].loc[pool].nunique()))


@dataclass(frozen=True)
class KnnGeneration:
    """The kNN rung's T_gen for the rows asked for, the k CV chose and its CV error."""

    t_gen: dict[str, np.ndarray]
    k: int
    cv_mse: float


def knn_generate(
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    pool: Sequence[str],
    rows: Sequence[str],
    *,
    ks: Sequence[int],
    seed: int,
    n_folds: int = KNN_FOLDS,
) -> KnnGeneration:
    """A1: the mean real T of the k nearest pool rows in V (Euclidean distance on V
    standardised by the pool's mean and sd; scikit-learn's KNeighborsRegressor, uniform
    weights), k chosen among `ks` (config ``regime.knn_ks``) by `n_folds`-fold CV (seeded
    shuffle) of the mean squared error of the T prediction on the pool.

    A k larger than a CV training fold is not tried; with fewer than `n_folds` pool rows, or
    none of `ks` small enough, k is the smallest of `ks` capped at the pool size (no CV:
    ``cv_mse`` NaN). k = pool size gives every row the pool mean.
    """
    from sklearn.model_selection import GridSearchCV, KFold
    from sklearn.neighbors import KNeighborsRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    pool = [str(i) for i in pool]
    rows = [str(i) for i in rows]
    if not pool:
        raise ValueError("knn_generate: the pool is empty")
    if not ks or min(int(k) for k in ks) < 1:
        raise ValueError(f"knn_generate: ks must be integers >= 1, got {list(ks)!r}")
    v_pool, t_pool = (
        feature_block(vision, pool, what="knn_generate"),
        feature_block(t_real, pool, what="knn_generate"),
    )
    n = len(pool)
    fold_train = n - -(-n // n_folds) if n >= n_folds else 0  # the smallest CV training fold
    grid = sorted({int(k) for k in ks if int(k) <= fold_train})
    if n >= n_folds >= 2 and grid:
        search = GridSearchCV(
            make_pipeline(StandardScaler(), KNeighborsRegressor()),
            {"kneighborsregressor__n_neighbors": grid},
            scoring="neg_mean_squared_error",
            cv=KFold(n_folds, shuffle=True, random_state=int(seed)),
        ).fit(v_pool, t_pool)
        k = int(search.best_params_["kneighborsregressor__n_neighbors"])
        cv_mse = float(-search.best_score_)
    else:
        k, cv_mse = min(min(int(k) for k in ks), n), float("nan")
    model = make_pipeline(StandardScaler(), KNeighborsRegressor(n_neighbors=k)).fit(v_pool, t_pool)
    pred = model.predict(feature_block(vision, rows, what="knn_generate"))
    return KnnGeneration(dict(zip(rows, pred, strict=True)), k, cv_mse)


@dataclass(frozen=True)
class LadderRungs:
    """The T_gen of the ladder's rungs that need no diffusion sampling, plus the diffusion
    generator's mean (``gen_mean``), for the rows asked for; and what each rung chose."""

    t_gen: dict[str, dict[str, np.ndarray]]  # rung -> sample_id -> vector
    look_levels: tuple[int, ...]  # rows per back-off level of the look oracle, then pool mean
    n_looks: int
    knn_k: int
    ridge_alpha: float
    kernel_ridge: str  # the kernel ridge rung's fit in words (`KernelRidgeGeneration.describe`)

    def describe(self) -> str:
        return (
            f"look oracle: {self.n_looks} looks in the pool, rows per look level (finest "
            f"first, then the pool mean) {list(self.look_levels)}; kNN: k = {self.knn_k}; "
            f"ridge: alpha = {self.ridge_alpha:g}; kernel ridge: {self.kernel_ridge}"
        )


def ladder_rungs(
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    looks: Mapping[str, str] | pd.Series | Sequence[Mapping[str, str] | pd.Series],
    pool: Sequence[str],
    rows: Sequence[str],
    gen_mean: Mapping[str, np.ndarray] | None,
    *,
    regime: RegimeSettings,
    seed: int,
) -> LadderRungs:
    """Every rung of `LADDER` but the one-sample ``v_tgen`` for `rows`, each learnt from the
    pool only: `look_oracle`, `knn_generate`, ridge (`generate.ridge_generator.ridge_generate`, its
    conditional mean), kernel ridge (`generate.kernel_ridge_generator.kernel_ridge_generate`) and
    ``gen_mean`` (given: the mean of the diffusion generator's samples,
    `regime_generators.pool_generators`; None: no ``gen_mean`` rung, as in the positive
    control's, `generate.look_control`). `regime`: the settings the rungs read (``knn_ks``,
    ``look_min_rows``, the kernel ridge rung's grids and Nystroem threshold and rank).

    Raises ValueError when a row asked for is in the pool: the pool is unlabelled, the rows a
    probe reads are labelled or test rows, and a rung learnt from a row's own touch would hand
    it back."""
    from tacgen_lib.generate.kernel_ridge_generator import kernel_ridge_generate
    from tacgen_lib.generate.ridge_generator import ridge_generate

    pool = [str(i) for i in pool]
    rows = [str(i) for i in rows]
    shared = sorted(set(pool) & set(rows))
    if shared:
        raise ValueError(
            f"ladder_rungs: row {shared[0]!r} is in the pool ({len(shared)} such): a labelled "
            "or test row's T_gen is learnt from pool rows only"
        )
    ks, look_min_rows = regime.knn_ks, regime.look_min_rows
    oracle = look_oracle(t_real, looks, pool, rows, min_rows=look_min_rows)
    knn = knn_generate(vision, t_real, pool, rows, ks=ks, seed=seed)
    needed = {i: vision[i] for i in (*pool, *rows)}
    ridge = ridge_generate(needed, t_real, pool, seed=seed)
    kernel = kernel_ridge_generate(vision, t_real, pool, rows, regime=regime, seed=seed)
    t_gen = {
        "look_oracle": oracle.t_gen,
        "knn": knn.t_gen,
        "ridge": {i: ridge.mean[i] for i in rows},
        "kernel_ridge": kernel.t_gen,
    }
    if gen_mean is not None:
        t_gen["gen_mean"] = {i: np.asarray(gen_mean[i], np.float64) for i in rows}
    return LadderRungs(
        t_gen=t_gen,
        look_levels=oracle.levels,
        n_looks=oracle.n_looks,
        knn_k=knn.k,
        ridge_alpha=ridge.alpha,
        kernel_ridge=kernel.describe(),
    )
