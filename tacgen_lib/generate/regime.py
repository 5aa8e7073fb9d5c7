"""Where generated touch helps, and where it cannot: scarce labels against a paired pool.

On a natural-appearance corpus (`tacgen_lib.corpus.sim.samples`, design ``natural``: appearance
class = material class with probability rho) a generator trained on a large *unlabelled*
paired pool of (V, T) rows can carry what V predicts of touch into a probe fitted on few
labels. Learning with privileged information says such a gain needs (1) V to predict the label
at all (rho > 0), (2) a map from V too nonlinear for a probe on few labels, (3) a pool much
larger than the labelled set, and (4) it must shrink as labels grow and must beat a baseline
that uses the same pool without generating anything. This module draws the sets and fits every
arm on the same test rows:

- ``v`` / linear: the probes stage's probe on V (`fit_small_probe`, regulariser by CV on the
  N_L labelled rows over the regime's grid, which reaches the majority class); ``v`` /
  nonlinear: V + RBF Nystroem features of V (`fit_small_nonlinear`);
- the generator ladder (`generate.ladder`), each rung V + its T_gen with the linear and the
  nonlinear probe: ``look_oracle`` (A0, the positive control: the mean real T of the pool
  rows with the row's look), ``knn`` (A1), ``ridge``, ``kernel_ridge`` (RBF kernel ridge,
  nonlinear), ``gen_mean`` (A2, the mean of K diffusion samples) and ``v_tgen`` (A3, one
  sample: the paper's arm);
- ``v_tgen_shuffled`` / linear: V + T_gen of a generator trained on the pool with its pairs
  broken (a Sattolo cycle of the pool rows): what generation adds without the V-T link;
- ``distilled`` / linear and nonlinear: generalised distillation (Lopez-Paz et al. 2016), a
  pool-aware V-only baseline that generates nothing: a teacher on V + real T fitted on the N_L
  labelled rows labels the pool through the pool's real T; a student on V alone is fitted on
  the labelled rows (true labels) and the pool (the teacher's labels);
- ``v_treal`` / linear: V + real T, the reference;
- ``v_ceiling`` / linear and nonlinear: the V probes fitted on every non-test row with its
  true label: the best a function of V reaches with every label, the bound that matters for
  every arm built on V. Its nonlinear probe is the visibility check's, the exact RBF-kernel
  probe (`fit_kernel_probe`: an SVM, kernel ridge for a continuous target), not the arms'
  Nystroem map, whose rank (the feature width) caps it on every non-test row; above
  ``regime.nystroem_above`` rows its kernel ridge takes ``regime.nystroem_rank`` Nystroem
  features, as the kernel ridge rung does (the exact solve grows as the cube of the rows), and
  its SVM's grid is chosen by CV on a draw of that many rows, then refitted on every row;
- ``vision_ceiling`` / oracle: the probe on the true appearance class (one-hot) and the
  visible shape and size, fitted on every non-test row: the best any function of appearance
  reaches (an oracle no arm can use).

Every score carries a fixed-test bootstrap CI; the Deltas against linear and nonlinear V are
paired on the same resamples (drawn once per target and shared by every arm). ``gap_closed`` =
(arm - nonlinear V) / (real - nonlinear V); ``headroom_captured`` = (arm - nonlinear V) / (V
ceiling - nonlinear V), the V ceiling being the nonlinear one, NaN where that headroom's paired
CI does not lie above 0 (`regime_arms.headroom_captured`: within its noise); ``majority`` is the score of
predicting the labelled rows' majority class (their mean, for ridge) on the test rows, and
``below_majority`` flags an arm that scores less. ``delta_vs_distilled`` = arm - generalised
distillation with the same probe (linear for the oracle and real arms).

Each seed draws ``label_draws`` labelled sets that share its pool and its generators
(`RegimeSets.labelled_draw`); the summary's ``draw`` says which.

The sets (labelled, pool, test) and the settings live in `regime_sets`, which the DAG and the
generator jobs import without scikit-learn; the arms, the designs they are fitted on and a
cell's summary rows in `regime_arms`; this module re-exports them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.ladder import LADDER
from tacgen_lib.generate.regime_arms import (
    ARMS,
    SUMMARY_COLUMNS,
    RegimeTarget,
    appearance_design,
    cell_rows,
    distillation_rows,
    gap_closed,
    regime_probe_settings,
    regime_test_rows,
)
from tacgen_lib.generate.regime_sets import (
    RegimeSets,
    RegimeSettings,
    assert_regime_disjoint,
    check_regime_sizes,
    draw_regime_sets,
    job_regime_sets,
)
from tacgen_lib.generate.small_probes import (
    SmallFit,
    fit_kernel_probe,
    fit_small_nonlinear,
    fit_small_probe,
)
from tacgen_lib.probes.bootstrap import (
    resample_indices,
)
from tacgen_lib.probes.rows import baseline_score
from tacgen_lib.runtime.workers import fork_map

if TYPE_CHECKING:
    from tacgen_lib.generate.visibility import VisibilitySettings

__all__ = [
    "ARMS",
    "LADDER",
    "SUMMARY_COLUMNS",
    "RegimeSets",
    "RegimeSettings",
    "RegimeTarget",
    "appearance_design",
    "assert_regime_disjoint",
    "check_regime_sizes",
    "draw_regime_sets",
    "evaluate_regime",
    "job_regime_sets",
    "fit_small_probe",
    "gap_closed",
    "distillation_rows",
    "regime_probe_settings",
    "regime_test_rows",
]


@dataclass(frozen=True)
class _CellFeatures:
    """What every cell of `evaluate_regime` reads: the features by sample_id (V, real T, the
    generated T of each pool and pairing, the ladder's rungs), the nonlinear probes' gamma
    multiples and the fixed-test bootstrap's resamples."""

    vision: Mapping[str, np.ndarray]
    t_real: Mapping[str, np.ndarray]
    t_gen: Mapping[tuple[int, str], Mapping[str, np.ndarray]]
    ladder: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]]
    gammas: Sequence[float]
    bootstrap: int
    distil: bool


def evaluate_regime(
    targets: Sequence[RegimeTarget],
    sets: RegimeSets,
    regime: RegimeSettings,
    ceiling: VisibilitySettings | None,
    *,
    corpus: str,
    rho: float,
    seed: int,
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    t_gen: Mapping[tuple[int, str], Mapping[str, np.ndarray]],
    ladder: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]],
    gammas: Sequence[float],
    n_classes: int,
    progress: Any = None,
    workers: int = 1,
    distil: bool = True,
) -> pd.DataFrame:
    """Every arm (`ARMS`) of every (labelled draw, N_L, N_P) cell of one corpus x seed, per
    target: ``regime.label_draws`` draws x ``regime.n_labelled`` x ``regime.n_pool``, each
    score with its fixed-test bootstrap CI (``regime.bootstrap`` resamples; config
    ``regime``). `gammas`: the nonlinear arms' RBF gamma multiples (config
    ``generate.nonlinear_gammas``).

    t_gen: (n_pool, "real" | "shuffled") -> sample_id -> one generated tactile sample (the
    ``v_tgen`` rung and the shuffled-pool arm); ladder: n_pool -> rung -> sample_id -> T_gen
    of the other rungs of `LADDER` (look_oracle, knn, ridge, kernel_ridge, gen_mean). Both hold at least the
    labelled rows of every draw and the test rows. The (target, draw, N_L) cells are
    independent: `workers` forked processes compute them (`runtime.workers.fork_map`, the same
    rows for any number of workers), the costliest (logistic targets, large N_L) first.
    ``ceiling.gammas`` x ``ceiling.C``: the grid of the V ceiling's kernel probe (config
    ``features.visibility``: the visibility check's nonlinear probe).

    The positive control (`generate.look_control`) runs the same cells on its own touch:
    `t_real` its T_control, `ladder` the rungs that need no diffusion, `t_gen` empty, and
    ``ceiling=None``, ``distil=False``: a cell fits only the arms whose inputs it is given
    (the V ceiling does not depend on touch; generalised distillation is left out).
    Returns rows with `SUMMARY_COLUMNS`, ordered by target, draw, N_L and N_P.
    """
    say = progress or (lambda _m: None)
    base = {"corpus": corpus, "rho": float(rho), "seed": int(seed)}
    features = _CellFeatures(
        vision, t_real, t_gen, ladder, tuple(gammas), int(regime.bootstrap), bool(distil)
    )
    # the ceilings of each target (fitted on every non-test row), then the cells
    ceilings = (
        fork_map(
            lambda tgt: _ceilings(tgt, vision, n_classes, ceiling=ceiling, regime=regime),
            targets,
            workers,
        )
        if ceiling is not None
        else [{} for _ in targets]
    )
    cells = [
        (t, d, int(n_l))
        for t in range(len(targets))
        for d in range(int(regime.label_draws))
        for n_l in sorted(map(int, regime.n_labelled))
    ]

    def one_cell(cell: tuple[int, int, int]) -> list[dict]:
        t, draw, n_l = cell
        rows = _labelled_cell(
            targets[t],
            ceilings[t],
            sets,
            draw,
            n_l,
            sorted(int(n) for n in regime.n_pool),
            features,
            base=base,
        )
        say(f"{corpus} seed {seed} draw {draw} {targets[t].rows.target}: N_L={n_l} done")
        return rows

    def cost(cell: tuple[int, int, int]) -> float:  # logistic CV dominates, growing with N_L
        return (10.0 if targets[cell[0]].settings.kind == "logistic" else 1.0) * (cell[2] + 64)

    out = [row for rows in fork_map(one_cell, cells, workers, cost=cost) for row in rows]
    return pd.DataFrame(out, columns=list(SUMMARY_COLUMNS))


def _labels(tgt: RegimeTarget, ids: Sequence) -> np.ndarray:
    label_of = dict(zip(map(str, tgt.rows.train_ids), tgt.rows.y_train, strict=True))
    y = np.array([label_of[str(i)] for i in ids], dtype=object)
    return y.astype(np.float64) if tgt.settings.kind == "ridge" else y


def _labelled_cell(
    tgt: RegimeTarget,
    ceilings: Mapping[tuple[str, str], SmallFit],
    sets: RegimeSets,
    draw: int,
    n_l: int,
    n_pool: Sequence[int],
    features: _CellFeatures,
    *,
    base: dict,
) -> list[dict]:
    """The rows of every arm of one target at one labelled draw and size, for every pool."""
    vision, t_real, t_gen, ladder = (
        features.vision,
        features.t_real,
        features.t_gen,
        features.ladder,
    )
    gammas, bootstrap = features.gammas, features.bootstrap
    rows, ps = tgt.rows, tgt.settings
    metric = ps.metric
    test = np.asarray(rows.test_ids, dtype=object)
    y_test = np.asarray(rows.y_test)
    v_te, t_te = feature_block(vision, test), feature_block(t_real, test)
    d_t = t_te.shape[1]
    idx = resample_indices(len(test), int(bootstrap), ps.seed)
    lab = sets.labelled_ids(n_l, draw)
    y_lab = _labels(tgt, lab)
    v_lab, t_lab = feature_block(vision, lab), feature_block(t_real, lab)
    fits: dict[tuple[str, str], SmallFit] = {
        ("v", "linear"): fit_small_probe(v_lab, y_lab, v_te, ps),
        ("v", "nonlinear"): fit_small_nonlinear(
            v_lab, y_lab, v_te, ps, gammas=gammas, n_components=d_t
        ),
        ("v_treal", "linear"): fit_small_probe(
            np.hstack([v_lab, t_lab]), y_lab, np.hstack([v_te, t_te]), ps
        ),
        **ceilings,
    }
    cell_base = {
        **base,
        "draw": int(draw),
        "n_labelled": n_l,
        "target": rows.target,
        "kind": ps.kind,
        "metric": metric,
        "n_test": len(test),
        "n_labelled_classes": (len(set(map(str, y_lab))) if ps.kind == "logistic" else 0),
        # the constant prediction a probe can fall back to (majority class / mean)
        "majority": baseline_score(y_lab, y_test, metric),
    }
    out: list[dict] = []
    for n_p in n_pool:
        pool = sets.pool_ids(n_p)
        cell = dict(fits)
        rungs = dict(ladder[n_p])
        if (n_p, "real") in t_gen:
            rungs["v_tgen"] = t_gen[(n_p, "real")]
        # the nonlinear probes of the rungs and of the distillation student take the gamma
        # multiple (of their own input's median heuristic) that CV chose for nonlinear V on
        # these labels, as the student always did; all of `gammas` where that probe could not
        # run CV. One CV over gammas per cell instead of one per arm
        g_nl = fits[("v", "nonlinear")].gamma_multiple
        g_arms = [g_nl] if np.isfinite(g_nl) else gammas
        for rung in (r for r in LADDER if r in rungs):
            x_lab = np.hstack([v_lab, feature_block(rungs[rung], lab)])
            x_te = np.hstack([v_te, feature_block(rungs[rung], test)])
            cell[(rung, "linear")] = fit_small_probe(x_lab, y_lab, x_te, ps)
            cell[(rung, "nonlinear")] = fit_small_nonlinear(
                x_lab, y_lab, x_te, ps, gammas=g_arms, n_components=d_t
            )
        if (n_p, "shuffled") in t_gen:
            shuf = t_gen[(n_p, "shuffled")]
            cell[("v_tgen_shuffled", "linear")] = fit_small_probe(
                np.hstack([v_lab, feature_block(shuf, lab)]),
                y_lab,
                np.hstack([v_te, feature_block(shuf, test)]),
                ps,
            )
        if features.distil:
            v_pool, t_pool = feature_block(vision, pool), feature_block(t_real, pool)
            x_gd, y_gd = distillation_rows(v_lab, t_lab, y_lab, v_pool, t_pool, ps)
            cell[("distilled", "linear")] = fit_small_probe(x_gd, y_gd, v_te, ps)
            cell[("distilled", "nonlinear")] = fit_small_nonlinear(
                x_gd, y_gd, v_te, ps, gammas=g_arms, n_components=d_t
            )
        out += cell_rows(cell, y_test, idx, metric, base={**cell_base, "n_pool": n_p})
    return out


def _ceilings(
    tgt: RegimeTarget,
    vision: Mapping[str, np.ndarray],
    n_classes: int,
    *,
    ceiling: VisibilitySettings,
    regime: RegimeSettings,
) -> dict[tuple[str, str], SmallFit]:
    """The arms fitted once per target on every non-test row with its true label: the V
    ceiling (the linear V probe, and the kernel probe with the grid ``ceiling.gammas`` x
    ``ceiling.C``; above ``regime.nystroem_above`` rows its kernel ridge on
    ``regime.nystroem_rank`` Nystroem features, as the kernel ridge rung's, and its SVM's grid
    chosen on a draw of that many rows, `fit_kernel_probe`) and the vision ceiling (the
    oracle probe on the true appearance class + visible shape and size)."""
    rows, ps = tgt.rows, replace(tgt.settings, cv_repeats=1)
    train = [str(i) for i in rows.train_ids]
    test = [str(i) for i in rows.test_ids]
    y = _labels(tgt, train)
    v_tr, v_te = feature_block(vision, train), feature_block(vision, test)
    x_tr, x_te = appearance_design(
        tgt.manifest.loc[train],
        tgt.manifest.loc[test],
        log_target=rows.target.startswith("log_"),
        n_classes=n_classes,
    )
    return {
        ("v_ceiling", "linear"): fit_small_probe(v_tr, y, v_te, ps),
        ("v_ceiling", "nonlinear"): fit_kernel_probe(
            v_tr,
            y,
            v_te,
            ps,
            gammas=ceiling.gammas,
            C=ceiling.C,
            large=(regime.nystroem_above, regime.nystroem_rank),
        ),
        ("vision_ceiling", "oracle"): fit_small_probe(x_tr, y, x_te, ps),
    }
