"""Where generated touch helps, and where it cannot: scarce labels against a paired pool.

On a natural-appearance corpus (`tacgen_lib.corpus.sim.corpus`, design ``natural``: appearance
class = material class with probability rho) a generator trained on a large *unlabelled*
paired pool of (V, T) rows can carry what V predicts of touch into a probe fitted on few
labels. Learning with privileged information says such a gain needs (1) V to predict the label
at all (rho > 0), (2) a map from V too nonlinear for a probe on few labels, (3) a pool much
larger than the labelled set, and (4) it must shrink as labels grow and must beat a baseline
that uses the same pool without generating anything. This module draws the sets and fits every
arm on the same test rows:

- ``v`` / linear: the probes stage's probe on V (`fit_probe`, regulariser by CV on the N_L
  labelled rows); ``v`` / nonlinear: V + RBF Nystroem features of V
  (`baselines.nonlinear_baseline`, gamma and regulariser by CV on the same rows);
- ``v_tgen`` / linear and nonlinear: V + T_gen, T_gen from the diffusion generator trained on
  the pool (`regime_generators`);
- ``v_tgen_shuffled`` / linear: V + T_gen of a generator trained on the pool with its pairs
  broken (a Sattolo cycle of the pool rows): what generation adds without the V-T link;
- ``distilled`` / linear and nonlinear: generalised distillation (Lopez-Paz et al. 2016), a
  pool-aware V-only baseline that generates nothing: a teacher on V + real T fitted on the N_L
  labelled rows labels the pool through the pool's real T; a student on V alone is fitted on
  the labelled rows (true labels) and the pool (the teacher's labels). If it matches V +
  T_gen, the value lies in the pool, not in generating touch;
- ``v_treal`` / linear: V + real T, the reference;
- ``vision_ceiling`` / oracle: the best score a function of appearance reaches, from the known
  generative process: the probe on the true appearance class (one-hot) and the visible shape
  and size, fitted on every non-test row with its true label (an oracle no arm can use).

Every score carries a 5,000-resample fixed-test bootstrap CI; the Deltas against linear and
nonlinear V are paired on the same resamples (drawn once per target and shared by every arm).
``gap_closed`` = (arm - nonlinear V) / (real - nonlinear V); ``delta_vs_distilled`` = arm -
generalised distillation with the same probe (linear for the linear, oracle and real arms).

The sets (labelled, pool, test) and the settings live in `regime_sets`, which the DAG and the
generator jobs import without scikit-learn; this module re-exports them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.generate.baselines import nonlinear_baseline
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.generate.regime_sets import (
    RegimeSets,
    RegimeSettings,
    assert_regime_disjoint,
    check_regime_sizes,
    draw_regime_sets,
    job_regime_sets,
)
from tacgen_lib.probes.bootstrap import (
    percentile_interval,
    resample_indices,
    score_interval,
    score_resamples,
)
from tacgen_lib.probes.fit import fit_probe
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.rows import FamilyRows, visible_design
from tacgen_lib.probes.settings import ProbeSettings
from tacgen_lib.runtime.workers import fork_map

__all__ = [
    "ARMS",
    "SUMMARY_COLUMNS",
    "RegimeSets",
    "RegimeSettings",
    "appearance_check",
    "appearance_design",
    "assert_regime_disjoint",
    "check_regime_sizes",
    "draw_regime_sets",
    "evaluate_regime",
    "job_regime_sets",
    "fit_small_probe",
    "gap_closed",
    "distillation_rows",
    "regime_test_rows",
]

#: (arm, probe) pairs of a regime cell, in report order.
ARMS: tuple[tuple[str, str], ...] = (
    ("v", "linear"),
    ("v", "nonlinear"),
    ("v_tgen", "linear"),
    ("v_tgen", "nonlinear"),
    ("v_tgen_shuffled", "linear"),
    ("distilled", "linear"),
    ("distilled", "nonlinear"),
    ("v_treal", "linear"),
    ("vision_ceiling", "oracle"),
)

#: Columns of ``results/generate/regime/summary.parquet`` (one row per cell x target x arm).
SUMMARY_COLUMNS = (
    "row_id",
    "corpus",
    "rho",
    "n_labelled",
    "n_pool",
    "seed",
    "target",
    "kind",
    "metric",
    "arm",
    "probe",
    "score",
    "ci_low",
    "ci_high",
    "delta_vs_linear_v",
    "ci_low_vs_linear_v",
    "ci_high_vs_linear_v",
    "delta_vs_nonlinear_v",
    "ci_low_vs_nonlinear_v",
    "ci_high_vs_nonlinear_v",
    "gap_closed",
    "delta_vs_distilled",
    "ci_low_vs_distilled",
    "ci_high_vs_distilled",
    "reg",
    "reg_source",
    "n_test",
    "n_labelled_classes",
)


def regime_test_rows(rows: FamilyRows, sets: RegimeSets) -> FamilyRows:
    """`rows` (a target's `family_rows`) with its test rows checked to be the sets' test rows."""
    if set(map(str, rows.test_ids)) != set(map(str, sets.test)):
        raise ValueError(
            f"regime: target {rows.target!r} of corpus {rows.corpus!r} has test rows other than "
            "the split's (a test row without a label?)"
        )
    return rows


# --------------------------------------------------------------------------- probes


@dataclass(frozen=True)
class SmallFit:
    """A probe fitted on few rows: test predictions, regulariser and how it was chosen."""

    pred: np.ndarray
    reg: float
    source: str  # "cv" | "single class: constant" | "fixed C (a class with < 2 rows)"
    gamma_multiple: float = math.nan  # a nonlinear probe's RBF gamma / median heuristic


def _cv_impossible(y: np.ndarray, settings: ProbeSettings) -> str:
    """Why the family's CV cannot run on these labels ("" when it can): a logistic probe's
    labels holding a single class, or a class with one row (stratified CV needs two)."""
    if settings.kind != "logistic":
        return ""
    classes, counts = np.unique(np.asarray(y).astype(str), return_counts=True)
    if classes.size < 2:
        return "single class: constant"
    if counts.min() < 2:
        return "fixed C (a class with < 2 rows)"
    return ""


def fit_small_probe(
    x_train: np.ndarray, y_train: np.ndarray, x_test: np.ndarray, settings: ProbeSettings
) -> SmallFit:
    """The probes stage's probe (`fit_probe`, CV over the family's grid) on possibly tiny
    labelled sets, with the two cases CV cannot handle made explicit (`_cv_impossible`):

    - a single class among the labelled rows: the constant prediction of that class;
    - a class with one labelled row (stratified CV needs two): the logistic probe at the
      middle C of the grid, refitted on all rows (``reg_source`` says so).
    """
    y = np.asarray(y_train)
    why = _cv_impossible(y, settings)
    if why.startswith("single class"):
        return SmallFit(np.full(len(x_test), y[0], dtype=object), math.nan, why)
    if why:
        grid = sorted(float(c) for c in settings.C)
        c_mid = grid[len(grid) // 2]
        from tacgen_lib.probes.logistic import FixedLogistic  # scikit-learn: only where fitted

        pred = FixedLogistic(c_mid).fit_predict(x_train, y, x_test)
        return SmallFit(np.asarray(pred, dtype=object), c_mid, why)
    fit = fit_probe(x_train, y, x_test, settings)
    return SmallFit(np.asarray(fit.pred_test), float(fit.reg), "cv")


def _nonlinear(
    x_train: np.ndarray,
    y_train: np.ndarray,
    x_test: np.ndarray,
    settings: ProbeSettings,
    *,
    gammas: Sequence[float],
    n_components: int,
) -> SmallFit:
    """The nonlinear V baseline's probe on [x, phi(x)] (`nonlinear_baseline`), or the
    `fit_small_probe` fallback where CV cannot run on these labels."""
    y = np.asarray(y_train)
    if _cv_impossible(y, settings):
        return fit_small_probe(x_train, y, x_test, settings)
    nl = nonlinear_baseline(
        x_train, x_test, y, settings, gammas=gammas, n_components=n_components, seed=settings.seed
    )
    return SmallFit(np.asarray(nl.probe.pred_test), float(nl.probe.reg), "cv", nl.multiple)


def distillation_rows(
    v_lab: np.ndarray,
    t_lab: np.ndarray,
    y_lab: np.ndarray,
    v_pool: np.ndarray,
    t_pool: np.ndarray,
    settings: ProbeSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """The student's training rows of generalised distillation (Lopez-Paz et al. 2016), with
    hard labels: the labelled rows' V with their true labels, then the pool rows' V with the
    labels of a teacher, the probe on [V, real T] fitted on the labelled rows, predicted
    through the pool's real touch. Returns (x, y)."""
    teacher = fit_small_probe(
        np.hstack([v_lab, t_lab]), y_lab, np.hstack([v_pool, t_pool]), settings
    )
    if settings.kind == "ridge":
        y_all = np.concatenate([np.asarray(y_lab, np.float64), teacher.pred.astype(np.float64)])
    else:
        y_all = np.concatenate([np.asarray(y_lab, dtype=object), teacher.pred.astype(object)])
    return np.vstack([v_lab, v_pool]), y_all


def appearance_design(
    train: pd.DataFrame, test: pd.DataFrame, *, log_target: bool, n_classes: int
) -> tuple[np.ndarray, np.ndarray]:
    """The vision ceiling's design: one-hot of the true appearance class (``appearance_id``,
    0..n_classes-1) beside the visible shape and size (`visible_design`); for mass targets
    the class one-hot times the size term too (mass = density x volume: E[mass | appearance,
    size] is E[density | appearance] x volume)."""
    vis_tr, vis_te = visible_design(train, test, log_target=log_target)

    def onehot(frame: pd.DataFrame) -> np.ndarray:
        ids = frame["appearance_id"].to_numpy(dtype=np.int64)
        return (ids[:, None] == np.arange(n_classes)[None, :]).astype(np.float64)

    oh_tr, oh_te = onehot(train), onehot(test)
    size_tr = train["scale"].to_numpy(np.float64) ** 3
    size_te = test["scale"].to_numpy(np.float64) ** 3
    if log_target:
        return np.hstack([oh_tr, vis_tr]), np.hstack([oh_te, vis_te])
    scale = size_tr.std() or 1.0
    return (
        np.hstack([oh_tr, vis_tr, oh_tr * (size_tr / scale)[:, None]]),
        np.hstack([oh_te, vis_te, oh_te * (size_te / scale)[:, None]]),
    )


def gap_closed(arm: float, nonlinear_v: float, real: float) -> float:
    """(arm - nonlinear V) / (real - nonlinear V): 0 = no better than nonlinear V, 1 = as good
    as real touch; NaN when real touch is no better than nonlinear V (nothing to close)."""
    gap = real - nonlinear_v
    if not np.isfinite(gap) or gap <= 0:
        return math.nan
    return (arm - nonlinear_v) / gap


# --------------------------------------------------------------------------- evaluation


@dataclass(frozen=True)
class RegimeTarget:
    """One target of the regime: its rows (train = every non-test row, test = the test
    split), its probe settings and the manifest rows of the vision ceiling."""

    rows: FamilyRows
    settings: ProbeSettings
    manifest: pd.DataFrame  # sample_id-indexed: appearance_id, shape, scale


def evaluate_regime(
    targets: Sequence[RegimeTarget],
    sets: RegimeSets,
    *,
    corpus: str,
    rho: float,
    seed: int,
    n_labelled: Sequence[int],
    n_pool: Sequence[int],
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    t_gen: Mapping[tuple[int, str], Mapping[str, np.ndarray]],
    gammas: Sequence[float],
    bootstrap: int,
    n_classes: int,
    progress: Any = None,
    workers: int = 1,
) -> pd.DataFrame:
    """Every arm (`ARMS`) of every (N_L, N_P) cell of one corpus x seed, per target.

    t_gen: (n_pool, "real" | "shuffled") -> sample_id -> generated tactile vector, for at
    least the labelled and test rows. The (target, N_L) cells are independent: `workers`
    forked processes compute them (`runtime.workers.fork_map`, the same rows for any number
    of workers), the costliest (logistic targets, large N_L) first. Returns rows with
    `SUMMARY_COLUMNS`, ordered by target, N_L and N_P.
    """
    say = progress or (lambda _m: None)
    base = {"corpus": corpus, "rho": float(rho), "seed": int(seed)}
    # the vision ceiling of each target (fitted on every non-test row), then the cells
    ceilings = fork_map(lambda tgt: _vision_ceiling(tgt, sets, n_classes), targets, workers)
    cells = [(t, int(n_l)) for t in range(len(targets)) for n_l in sorted(map(int, n_labelled))]

    def one_cell(cell: tuple[int, int]) -> list[dict]:
        t, n_l = cell
        rows = _labelled_cell(
            targets[t],
            ceilings[t],
            sets,
            n_l,
            sorted(int(n) for n in n_pool),
            vision=vision,
            t_real=t_real,
            t_gen=t_gen,
            gammas=gammas,
            bootstrap=bootstrap,
            base=base,
        )
        say(f"{corpus} seed {seed} {targets[t].rows.target}: N_L={n_l} done")
        return rows

    def cost(cell: tuple[int, int]) -> float:  # logistic CV dominates, growing with N_L
        return (10.0 if targets[cell[0]].settings.kind == "logistic" else 1.0) * (cell[1] + 64)

    out = [row for rows in fork_map(one_cell, cells, workers, cost=cost) for row in rows]
    return pd.DataFrame(out, columns=list(SUMMARY_COLUMNS))


def _labelled_cell(
    tgt: RegimeTarget,
    ceiling: SmallFit,
    sets: RegimeSets,
    n_l: int,
    n_pool: Sequence[int],
    *,
    vision: Mapping[str, np.ndarray],
    t_real: Mapping[str, np.ndarray],
    t_gen: Mapping[tuple[int, str], Mapping[str, np.ndarray]],
    gammas: Sequence[float],
    bootstrap: int,
    base: dict,
) -> list[dict]:
    """The rows of every arm of one target at one labelled size, for every pool size."""
    rows, ps = tgt.rows, tgt.settings
    metric = ps.metric
    test = np.asarray(rows.test_ids, dtype=object)
    y_test = np.asarray(rows.y_test)
    label_of = dict(zip(map(str, rows.train_ids), rows.y_train, strict=True))
    v_te, t_te = feature_block(vision, test), feature_block(t_real, test)
    d_t = t_te.shape[1]
    idx = resample_indices(len(test), int(bootstrap), ps.seed)
    lab = sets.labelled_ids(n_l)
    y_lab = np.array([label_of[str(i)] for i in lab], dtype=object)
    if ps.kind == "ridge":
        y_lab = y_lab.astype(np.float64)
    v_lab, t_lab = feature_block(vision, lab), feature_block(t_real, lab)
    fits: dict[tuple[str, str], SmallFit] = {
        ("v", "linear"): fit_small_probe(v_lab, y_lab, v_te, ps),
        ("v", "nonlinear"): _nonlinear(v_lab, y_lab, v_te, ps, gammas=gammas, n_components=d_t),
        ("v_treal", "linear"): fit_small_probe(
            np.hstack([v_lab, t_lab]), y_lab, np.hstack([v_te, t_te]), ps
        ),
        ("vision_ceiling", "oracle"): ceiling,
    }
    out: list[dict] = []
    for n_p in n_pool:
        pool = sets.pool_ids(n_p)
        v_pool, t_pool = feature_block(vision, pool), feature_block(t_real, pool)
        cell = dict(fits)
        gen, shuf = t_gen[(n_p, "real")], t_gen[(n_p, "shuffled")]
        g_lab, g_te = feature_block(gen, lab), feature_block(gen, test)
        s_lab, s_te = feature_block(shuf, lab), feature_block(shuf, test)
        x_lab, x_te = np.hstack([v_lab, g_lab]), np.hstack([v_te, g_te])
        cell[("v_tgen", "linear")] = fit_small_probe(x_lab, y_lab, x_te, ps)
        cell[("v_tgen", "nonlinear")] = _nonlinear(
            x_lab, y_lab, x_te, ps, gammas=gammas, n_components=d_t
        )
        cell[("v_tgen_shuffled", "linear")] = fit_small_probe(
            np.hstack([v_lab, s_lab]), y_lab, np.hstack([v_te, s_te]), ps
        )
        # the student's gamma multiple: the one CV chose for nonlinear V on these labels
        # (all of `gammas` where that probe could not run CV)
        x_gd, y_gd = distillation_rows(v_lab, t_lab, y_lab, v_pool, t_pool, ps)
        g_nl = fits[("v", "nonlinear")].gamma_multiple
        cell[("distilled", "linear")] = fit_small_probe(x_gd, y_gd, v_te, ps)
        cell[("distilled", "nonlinear")] = _nonlinear(
            x_gd,
            y_gd,
            v_te,
            ps,
            gammas=[g_nl] if np.isfinite(g_nl) else gammas,
            n_components=d_t,
        )
        out += _cell_rows(
            cell,
            y_test,
            idx,
            metric,
            base={
                **base,
                "n_labelled": n_l,
                "n_pool": n_p,
                "target": rows.target,
                "kind": ps.kind,
                "metric": metric,
                "n_test": len(test),
                "n_labelled_classes": (len(set(map(str, y_lab))) if ps.kind == "logistic" else 0),
            },
        )
    return out


def _vision_ceiling(tgt: RegimeTarget, sets: RegimeSets, n_classes: int) -> SmallFit:
    """The oracle probe on true appearance class + visible shape and size, fitted on every
    non-test row (labelled and pool) with its true label."""
    rows, ps = tgt.rows, tgt.settings
    label_of = dict(zip(map(str, rows.train_ids), rows.y_train, strict=True))
    train = [str(i) for i in np.concatenate([sets.labelled, sets.pool]) if str(i) in label_of]
    test = [str(i) for i in rows.test_ids]
    x_tr, x_te = appearance_design(
        tgt.manifest.loc[train],
        tgt.manifest.loc[test],
        log_target=rows.target.startswith("log_"),
        n_classes=n_classes,
    )
    y = np.array([label_of[i] for i in train], dtype=object)
    if ps.kind == "ridge":
        y = y.astype(np.float64)
    return fit_small_probe(x_tr, y, x_te, replace(ps, cv_repeats=1))


def _cell_rows(
    fits: Mapping[tuple[str, str], SmallFit],
    y_test: np.ndarray,
    idx: np.ndarray,
    metric: str,
    *,
    base: dict,
) -> list[dict]:
    """One summary row per arm of a cell: score with CI, Deltas vs linear and nonlinear V
    and vs generalised distillation with the same probe (linear for the other arms).

    Every arm is scored on every fixed-test resample of `idx` at once (`score_resamples`:
    one count matrix for the cell); a CI is the percentile interval of an arm's resampled
    scores, a Delta's the interval of the paired differences, as `fixed_test_bootstrap`
    computes them for one pair of probes.
    """
    if metric == "r2":
        y_test = y_test.astype(np.float64)
    keys = list(fits)
    for k in keys:
        pred = np.asarray(fits[k].pred)
        if pred.shape != y_test.shape or (
            metric == "r2" and not np.isfinite(pred.astype(np.float64)).all()
        ):
            raise ValueError(
                f"regime cell {base['corpus']} N_L={base['n_labelled']} {base['target']}: "
                f"arm {'/'.join(k)} predicted {pred.shape} values, not {y_test.shape} finite ones"
            )
    resampled, _ = score_resamples(metric, y_test, [fits[k].pred for k in keys], idx)
    on_resamples = dict(zip(keys, resampled, strict=True))
    full = {k: score(metric, y_test, fits[k].pred) for k in keys}

    def versus(ref: tuple[str, str], k: tuple[str, str]) -> tuple[float, float, float]:
        lo, hi = percentile_interval(on_resamples[k] - on_resamples[ref])
        return full[k] - full[ref], lo, hi

    real, nl = full[("v_treal", "linear")], full[("v", "nonlinear")]
    key = f"{base['corpus']}|{base['n_labelled']}|{base['n_pool']}|{base['seed']}|{base['target']}"
    rows = []
    for arm, probe in ARMS:
        k = (arm, probe)
        lo, hi = percentile_interval(on_resamples[k])
        d_lin, lo_lin, hi_lin = versus(("v", "linear"), k)
        d_nl, lo_nl, hi_nl = versus(("v", "nonlinear"), k)
        d_gd, lo_gd, hi_gd = versus(
            ("distilled", "nonlinear" if probe == "nonlinear" else "linear"), k
        )
        rows.append(
            {
                "row_id": f"{key}|{arm}|{probe}",
                **base,
                "arm": arm,
                "probe": probe,
                "score": full[k],
                "ci_low": lo,
                "ci_high": hi,
                "delta_vs_linear_v": d_lin,
                "ci_low_vs_linear_v": lo_lin,
                "ci_high_vs_linear_v": hi_lin,
                "delta_vs_nonlinear_v": d_nl,
                "ci_low_vs_nonlinear_v": lo_nl,
                "ci_high_vs_nonlinear_v": hi_nl,
                "gap_closed": gap_closed(full[k], nl, real),
                "delta_vs_distilled": d_gd,
                "ci_low_vs_distilled": lo_gd,
                "ci_high_vs_distilled": hi_gd,
                "reg": fits[k].reg,
                "reg_source": fits[k].source,
            }
        )
    return rows


def appearance_check(
    vision: Mapping[str, np.ndarray],
    appearance: pd.Series,
    sets: RegimeSets,
    settings: ProbeSettings,
    *,
    corpus: str,
    rho: float,
    seed: int,
    gammas: Sequence[float],
    bootstrap: int,
    progress: Any = None,
    workers: int = 1,
) -> pd.DataFrame:
    """How well V decodes the appearance class: the linear and the nonlinear V probe
    (logistic, regulariser by CV) fitted on every labelled and pool row, scored on the test
    rows with a fixed-test bootstrap CI. appearance: sample_id -> appearance class.

    The natural design builds the class as (colour + texture) mod k, so a linear probe on
    raw appearance should do worse than a nonlinear one; the report shows both. At every rho
    the class is uniform and the frame depends on the class, not on the material, so the
    accuracy is a property of the design, the same on every corpus of a rho grid (the DAG
    checks one). The two probes are fitted by `workers` forked processes (`fork_map`).
    """
    say = progress or (lambda _m: None)
    train = [str(i) for i in np.concatenate([sets.labelled, sets.pool])]
    test = [str(i) for i in sets.test]
    y_tr = appearance.loc[train].astype(str).to_numpy(dtype=object)
    y_te = appearance.loc[test].astype(str).to_numpy(dtype=object)
    v_tr, v_te = feature_block(vision, train), feature_block(vision, test)
    idx = resample_indices(len(test), int(bootstrap), settings.seed)

    def fit(probe: str) -> SmallFit:
        if probe == "linear":
            return fit_small_probe(v_tr, y_tr, v_te, settings)
        return _nonlinear(v_tr, y_tr, v_te, settings, gammas=gammas, n_components=v_tr.shape[1])

    out = []
    probes = ("linear", "nonlinear")
    for probe, fitted in zip(probes, fork_map(fit, probes, workers), strict=True):
        acc = score("accuracy", y_te, fitted.pred)
        lo, hi = score_interval("accuracy", y_te, fitted.pred, idx)
        say(f"appearance class, {probe} probe on V: accuracy {acc:.3f}")
        out.append(
            {
                "row_id": f"{corpus}|{seed}|appearance_class|{probe}",
                "corpus": corpus,
                "rho": float(rho),
                "seed": int(seed),
                "probe": probe,
                "score": acc,
                "ci_low": lo,
                "ci_high": hi,
                "chance": float(pd.Series(y_te).value_counts(normalize=True).max()),
                "n_train": len(train),
                "n_test": len(test),
            }
        )
    return pd.DataFrame(out)
