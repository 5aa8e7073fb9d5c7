"""The regime's sets and settings (`tacgen_lib.generate.regime`), apart from its probes so that
the DAG's parse-time size check and the generator jobs import no scikit-learn.

Sets (`draw_regime_sets`): the corpus's test split is the fixed, object-level test set; the
non-test rows are permuted with the cell seed; the first max(N_L) form the labelled order
(N_L = n takes its first n: the labelled sets are nested) and the next max(N_P) the pool
order (nested likewise). Labelled, pool and test rows are disjoint by construction and
`assert_regime_disjoint` checks it again against the split edge in every job.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.corpus.splits import LeakageError, assert_trainable
from tacgen_lib.io.schema import SchemaSettings, schema_fields

__all__ = [
    "NATURAL_PREFIX",
    "PAIRINGS",
    "natural_corpus_name",
    "natural_grid_ends",
    "regime_corpora",
    "RegimeSets",
    "RegimeSettings",
    "assert_regime_disjoint",
    "check_regime_sizes",
    "draw_regime_sets",
    "job_regime_sets",
    "pool_steps",
]

#: The name of the regime's natural corpus at rho: this prefix and rho's digits.
NATURAL_PREFIX = "sim_natural_r"


def natural_corpus_name(rho: float) -> str:
    """The corpus the regime draws at `rho` (0 -> sim_natural_r0, 0.5 -> sim_natural_r05,
    0.25 -> sim_natural_r025, 1 -> sim_natural_r1): a valid {corpus} wildcard."""
    rho = float(rho)
    if not 0.0 <= rho <= 1.0:
        raise ValueError(f"regime.rhos: {rho} is not in [0, 1]")
    return NATURAL_PREFIX + f"{rho:g}".replace(".", "")


def regime_corpora(regime: Mapping[str, Any] | None) -> dict[str, dict[str, Any]]:
    """Corpus name -> declaration of every natural corpus of config ``regime``: its
    ``corpus`` declaration once per value of ``rhos`` (with that ``rho``), in rhos order.
    The physics of a sample does not depend on rho (same seed), only what it looks like.
    Empty when the section is absent or ``rhos`` is empty."""
    if not regime or not regime.get("rhos"):
        return {}
    if not isinstance(regime.get("corpus"), Mapping):
        raise ValueError(
            "regime.corpus: the regime's natural corpus must be a corpus declaration (a "
            f"mapping of its keys), got {regime.get('corpus')!r}"
        )
    base = dict(regime["corpus"])
    if base.get("design") != "natural" or base.get("kind") != "simulated":
        raise ValueError(
            "regime.corpus: the regime draws a simulated corpus of design natural (its "
            f"appearance classes define the vision ceiling), got kind {base.get('kind')!r}, "
            f"design {base.get('design')!r}"
        )
    out: dict[str, dict[str, Any]] = {}
    for rho in regime["rhos"]:
        name = natural_corpus_name(rho)
        if name in out:
            raise ValueError(f"regime.rhos: {rho} and another value both name corpus {name!r}")
        out[name] = {**base, "rho": float(rho)}
    return out


def natural_grid_ends(regime: Mapping[str, Any] | None) -> tuple[list[str], list[str]]:
    """(ends, between) of the regime's rho grid: its corpora at rho = 0 and rho = 1, and the
    corpora between them, whose every frame is one of the ends' (a sample's appearance class
    is its draw at rho = 0 or its material, the class at rho = 1). Both empty unless both
    ends are in the grid: otherwise every corpus renders frames of its own."""
    grid = regime_corpora(regime)
    ends = [n for n, d in grid.items() if d["rho"] in (0.0, 1.0)]
    if len(ends) < 2:
        return [], []
    return ends, [n for n in grid if n not in ends]


#: The two generators of each pool: trained on its real pairs, or on re-paired ones.
PAIRINGS = ("real", "shuffled")


@dataclass(frozen=True)
@schema_fields("regime", skip=("corpus", "rhos", "targets"))
class RegimeSettings(SchemaSettings):
    """The regime grid and how its arms are fitted (config ``regime``).

    ``n_labelled`` / ``n_pool``: the label and pool sizes of the grid; ``seeds``: one per set
    draw and generator; ``label_draws``: labelled draws per seed, sharing the seed's pool and
    generators (`RegimeSets.labelled_draw`); ``targets``: target -> ridge | logistic;
    ``pool_val_fraction``: the share of the pool that only steers the generator's early
    stopping; ``steps``, ``batch_size``: the regime generators' step cap and batch (the rest of
    the model is config ``generate``'s), the cap growing with pools of more than
    ``steps_reference_pool`` rows at ``steps_pool_exponent`` (`pool_steps`); ``sampling_steps``, ``guidance``: the DDIM cell they
    are sampled with; ``gen_mean_samples``: the samples the ladder's ``gen_mean`` rung
    averages (`generate.ladder`); ``knn_ks``: the k its ``knn`` rung chooses among;
    ``kernel_ridge_gammas`` / ``kernel_ridge_lambdas``: the gamma multiples and penalties its
    ``kernel_ridge`` rung chooses among, on Nystroem features of rank ``nystroem_rank`` for
    pools of more than ``nystroem_above`` rows (`generate.kernel_ridge_generator`);
    ``look_min_rows``: the pool rows a look needs before its ``look_oracle`` rung averages
    them (else it backs off to a coarser look);
    ``bootstrap``: fixed-test resamples; ``C`` / ``lambdas``: the regime's probe grids, which
    reach penalties strong enough for a probe to fall back to the majority class or the mean
    (the probes stage keeps the paper's, config ``probes``).
    """


def pool_steps(steps: int, n_pool: int, regime: RegimeSettings) -> int:
    """The step cap of a regime generator trained on a pool of `n_pool` rows, `steps` being
    the cap of a pool of the reference size (config ``regime.steps``,
    `regime_generators.regime_generator_settings`):

        steps x max(1, N_P / steps_reference_pool) ^ steps_pool_exponent,

    rounded to the nearest integer (config ``regime.steps_reference_pool``,
    ``steps_pool_exponent``). A pool of at most ``steps_reference_pool`` rows takes `steps`
    exactly; with exponent 1 a larger pool takes as many passes over its rows (epochs, at the
    same batch) as the reference pool does, so a pool four times larger is not cut off after
    a quarter of the passes. Early stopping still ends training before the cap where the
    pool's validation loss stops improving.
    """
    ratio = max(1.0, int(n_pool) / int(regime.steps_reference_pool))
    if ratio == 1.0:
        return int(steps)
    return int(round(int(steps) * ratio ** float(regime.steps_pool_exponent)))


@dataclass(frozen=True)
class RegimeSets:
    """The draw of one regime seed: ``labelled`` (max N_L ids, nested by prefix), ``pool``
    (max N_P ids, nested by prefix) and ``test`` (the corpus's test split), all disjoint;
    ``spare``: the non-test rows in neither (they give the later labelled draws' rows).

    Labelled draw 0 is ``labelled``; draw d >= 1 (`labelled_draw`) re-draws the labelled
    order from the labelled and spare rows, so every draw shares the seed's pool (and its
    generators) and stays disjoint from the pool and the test rows."""

    labelled: np.ndarray
    pool: np.ndarray
    test: np.ndarray
    seed: int
    spare: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=object))

    def labelled_ids(self, n: int, draw: int = 0) -> np.ndarray:
        return self.labelled_draw(draw)[: int(n)]

    def pool_ids(self, n: int) -> np.ndarray:
        return self.pool[: int(n)]

    def labelled_draw(self, draw: int) -> np.ndarray:
        """The labelled order of draw `draw` (as long as ``labelled``): draw 0 is
        ``labelled``; a later draw permutes the sorted labelled and spare rows with
        ``default_rng([seed, 0x6C626C64, draw])`` and takes the first len(labelled)."""
        if int(draw) == 0:
            return self.labelled
        rows = np.sort(np.concatenate([self.labelled, self.spare]).astype(object))
        perm = np.random.default_rng([int(self.seed), 0x6C626C64, int(draw)]).permutation(len(rows))
        return rows[perm][: len(self.labelled)]

    def labelled_union(self, draws: int) -> np.ndarray:
        """Every row of labelled draws 0 .. draws - 1, sorted (the rows a job needs)."""
        return np.array(
            sorted({str(i) for d in range(int(draws)) for i in self.labelled_draw(d)}),
            dtype=object,
        )


def check_regime_sizes(
    corpus: str, n_rows: int, n_test: int, n_labelled: Sequence[int], n_pool: Sequence[int]
) -> None:
    """Refuse a grid whose labelled, pool and test sets cannot be drawn disjointly.

    The labelled and pool sets come from the corpus's n_rows - n_test non-test rows; each
    labelled set must hold at least 2 rows and each pool 2 (one to train on, one to stop
    early on). Raises ValueError naming the corpus and the sizes.
    """
    need = max(int(n) for n in n_labelled) + max(int(n) for n in n_pool)
    have = int(n_rows) - int(n_test)
    if need > have:
        raise ValueError(
            f"regime: corpus {corpus!r} has {have} non-test rows ({n_rows} rows, "
            f"{n_test} test), but the largest labelled set ({max(n_labelled)}) and the largest "
            f"pool ({max(n_pool)}) need {need} disjoint rows: raise the corpus's n or lower "
            "regime.n_labelled / n_pool"
        )
    if min(int(n) for n in n_labelled) < 2:
        raise ValueError(f"regime: corpus {corpus!r}: a labelled set needs >= 2 rows")
    if min(int(n) for n in n_pool) < 2:
        raise ValueError(f"regime: corpus {corpus!r}: a pool needs >= 2 rows")


def draw_regime_sets(
    splits: pd.DataFrame,
    corpus: str,
    *,
    n_labelled: int,
    n_pool: int,
    seed: int,
) -> RegimeSets:
    """The labelled order, the pool order and the test rows of `corpus` (module docstring).

    splits: the split edge (sample_id, corpus, split). The non-test rows, sorted by
    sample_id, are permuted with ``default_rng([seed, 0x7265676D])``; the first `n_labelled`
    are the labelled order, the next `n_pool` the pool order.
    """
    rows = splits.loc[splits["corpus"] == corpus].sort_values("sample_id")
    test = rows.loc[rows["split"] == "test", "sample_id"].to_numpy(dtype=object)
    rest = rows.loc[rows["split"] != "test", "sample_id"].to_numpy(dtype=object)
    check_regime_sizes(corpus, len(rows), len(test), [n_labelled], [n_pool])
    order = rest[np.random.default_rng([int(seed), 0x7265676D]).permutation(len(rest))]
    return RegimeSets(
        labelled=order[: int(n_labelled)],
        pool=order[int(n_labelled) : int(n_labelled) + int(n_pool)],
        test=test,
        spare=order[int(n_labelled) + int(n_pool) :],
        seed=int(seed),
    )


def assert_regime_disjoint(
    sets: RegimeSets, splits: pd.DataFrame, *, rule: str, draws: int = 1
) -> None:
    """Refuse overlapping sets, and any labelled or pool row that the split edge holds out,
    for labelled draws 0 .. draws - 1 (`RegimeSets.labelled_draw`).

    Raises LeakageError naming the rule, the sets and the first shared sample_id.
    """
    labelled = sets.labelled_union(draws) if draws > 1 else sets.labelled
    named = {"labelled": labelled, "pool": sets.pool, "test": sets.test}
    names = list(named)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            shared = sorted(set(map(str, named[a])) & set(map(str, named[b])))
            if shared:
                raise LeakageError(
                    f"rule {rule}: the regime's {a} and {b} sets share {len(shared)} row(s), "
                    f"e.g. sample_id {shared[0]!r}"
                )
    assert_trainable(list(labelled) + list(sets.pool), splits, rule=rule, allowed=("train", "val"))


def job_regime_sets(
    splits: pd.DataFrame, corpus: str, regime: RegimeSettings, seed: int, *, rule: str
) -> RegimeSets:
    """The sets a regime job of `corpus` x `seed` reads (`draw_regime_sets` at the largest
    labelled and pool sizes; smaller ones are their prefixes), refused by
    `assert_regime_disjoint` if they overlap or hold a held-out row: every rule that fits on
    them (generators on the pool, probes on labelled rows) trains on no test row."""
    sets = draw_regime_sets(
        splits,
        corpus,
        n_labelled=max(regime.n_labelled),
        n_pool=max(regime.n_pool),
        seed=seed,
    )
    assert_regime_disjoint(sets, splits, rule=rule, draws=regime.label_draws)
    return sets
