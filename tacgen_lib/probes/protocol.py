"""One probe family of the paper's protocol: inputs x fusions x controls -> tidy result rows.

This module owns the orchestration of a probe family (``probes.families.<name>`` in config):
which rows train and test the probes, which target is predicted, which V vs V+T comparisons
are made, which controls run on which comparison, and how every outcome becomes one tidy row.
The numerics it calls live in the sibling modules `ridge` and `logistic` (the probes), `fusion`
(V+T variants), `bootstrap` (the fixed-test CI) and `controls` (the controls and the paper's
criterion); file I/O lives in the rule scripts.

Protocol (paper, "Probes")
- Rows: train = the corpus's ``train`` + ``val`` split (the probe has no early stopping, so
  validation rows are ordinary training rows), test = its ``test`` split. For the
  appearance-controlled corpus the split is by object scale (train 0.15/0.20, test 0.25),
  fixed by the split edge. Rows without a label (real corpora) are dropped and counted.
- Target (`target_values`): a manifest column; ``log_mass`` = log(mass); logistic targets
  (``density`` as 3 classes, ``hardness`` soft/hard) are class labels (strings).
- Comparisons (`plan_comparisons`), V vs V+T always on the same rows:
  * ``raw``: V = vision features (pixel or vit), T = tactile ``vit`` features of the heads'
    preprocessing variant; every configured fusion (``concat`` always). A same-dimension
    fusion (mean, max, weighted) runs on raw features only when d_V == d_T and is
    otherwise recorded as a ``skipped`` row with the reason.
  * ``raw`` tactile ablation: T of every other preprocessing variant, ``concat`` with raw V.
  * ``aligned``: V_aligned vs fuse(V_aligned, T_aligned) for every fusion and alignment seed,
    in families whose V is ``vit`` only (`has_aligned_rows`): the heads project ViT features,
    so in a pixel-V family the aligned rows would compare against a ViT-derived V baseline
    unlike its raw rows, and repeat its ViT twin's rows exactly. A pixel-V family compares
    raw pixel V vs V+T; its aligned results live in the ``*_vit`` family of the same target.
- Regulariser: lambda (ridge) or C (logistic) by K-fold CV on the training rows only.
- Statistics per comparison: fixed-test bootstrap (stratified within strata when given),
  percentile 95% CI, p(Delta > 0).
- Controls (budget cap): train-resample diagnostic, tactile-permutation, label-permutation
  and dimension-matched random-feature controls run on the ``concat`` comparison of each input
  (raw with the heads' variant, and aligned per alignment seed) -- the comparisons the paper's
  claims rest on. Logistic controls (about 1,000 lbfgs refits per comparison) run on the raw
  concat and on the first alignment seed's aligned concat only, at lbfgs tol 1e-4
  (`CONTROL_TOL`, `LOGISTIC_CONTROL_ALIGN_SEEDS`). Other comparisons say
  ``controls = "not run"``; their ``delta_ctrl`` and ``criterion_met`` are null, not guessed.
- The paper's criterion (Delta >= 0.03, CI lower bound > 0, Delta_ctrl < Delta, with
  Delta_ctrl the tactile-permutation mean) is a column; nothing is filtered on it.
- Baselines that size a Delta (columns of every row of a family): ``baseline_score``, the
  test score of predicting the training mean (ridge) or the majority training class
  (logistic), `baseline_score`; and ``visible_score``, the test score of the same kind of
  probe on the attributes vision can see, shape and scale (`visible_design`: the best
  shape-only predictor of mass = density x volume(shape, scale) is linear in
  one-hot(shape) x scale^3, of log-mass in one-hot(shape) and log(scale)); NaN where the
  manifest has no shape and scale.

Protocol variants (`variants.PROTOCOLS`): ``settings.protocol`` picks the probe
`fit_probe` fits -- ``raw`` (the above), ``standardised`` (`scaling`) or ``mlp2`` (`mlp`) --
and every row carries a ``protocol`` column. `run_family` can restrict a variant to the
headline comparisons (``concat`` with the heads' variant, raw and aligned) and leave its
controls out (the default budget); the paper config runs everything under every variant.

Every row carries ``row_id`` = ``family|input|t~variant|fusion|a~align_seed|s~probe_seed|control``
(``...|s~probe_seed|p~protocol|control`` for a protocol other than ``raw``, so raw keys are
those from before the variants existed), unique within a run, the key of the probe edges.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from sklearn.exceptions import ConvergenceWarning

from tacgen_lib.io.config import settings_from
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
from tacgen_lib.probes.controls import (
    PairedRows,
    label_permutation_control,
    paper_criterion,
    random_feature_control,
    tactile_permutation_control,
    train_resample_diagnostic,
)
from tacgen_lib.probes.fusion import FUSIONS, fuse
from tacgen_lib.probes.logistic import FixedLogistic, fit_logistic
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.mlp import FixedMLP, MLPGrid, fit_mlp_probe
from tacgen_lib.probes.refits import FixedProbe
from tacgen_lib.probes.ridge import FixedRidge, fit_ridge_probe
from tacgen_lib.probes.scaling import FixedStandardisedRidge, fit_standardised_ridge
from tacgen_lib.probes.settings import check_families, has_aligned_rows
from tacgen_lib.probes.subsets import within_scale_split
from tacgen_lib.probes.variants import check_protocol

__all__ = [
    "BANDS",
    "class_order",
    "CONTROLS",
    "ComparisonSpec",
    "FamilyResult",
    "FamilyRows",
    "FittedProbe",
    "ProbeSettings",
    "compare",
    "confusion_counts",
    "family_rows",
    "baseline_score",
    "check_families",
    "fit_probe",
    "has_aligned_rows",
    "headline_plan",
    "plan_comparisons",
    "pool_strata",
    "row_id",
    "run_family",
    "strata_for",
    "target_values",
    "tidy",
    "visible_design",
    "visible_score",
]

#: The controls, in the order their rows are written.
CONTROLS = ("train_resample", "tactile_permutation", "label_permutation", "random_features")
#: Targets whose uncertainty bands travel with the results: target -> (low, high) columns.
BANDS = {"force_p50": ("force_p05", "force_p95")}
#: lbfgs tolerance of the logistic refits inside controls: scikit-learn's default. The main
#: probes use `probes.fit_logistic`'s tighter 1e-6. Controls are distributions over hundreds of
#: refits; at 1e-4 the hardness tactile-permutation Δ_ctrl moved by 0.004 against 1e-6 (0.013
#: vs 0.017), while 1e-6 made the batched train-resample refits of the 3-class density probe
#: run for minutes.
CONTROL_TOL = 1e-4
#: Logistic controls refit ~1,000 lbfgs problems per comparison, so they run on the raw concat
#: comparison and the aligned concat of this many alignment seeds (the first in sorted order);
#: ridge controls are batched solves and run on every concat comparison.
LOGISTIC_CONTROL_ALIGN_SEEDS = 1
#: The columns whose product defines the bootstrap strata of a controlled corpus.
CONTROLLED_STRATA = ("shape", "density", "scale")


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class ProbeSettings:
    """Everything a comparison needs from config ``probes`` for one family and probe seed."""

    kind: str  # "ridge" | "logistic"
    lambdas: tuple[float, ...]
    C: tuple[float, ...]
    folds: int
    bootstrap: int
    train_resamples: int
    permutations: int
    label_permutations: int
    random_draws: int
    seed: int
    min_delta: float = 0.03
    protocol: str = "raw"  # a name of `variants.PROTOCOLS`
    #: seed of the bootstrap resamples and control draws; None: `seed` (which also draws the
    #: CV folds). The cost sweep's probe knobs vary it alone to measure Monte Carlo error.
    resample_seed: int | None = None
    mlp: MLPGrid = field(default_factory=MLPGrid)  # the ``mlp2`` probe's grid

    def __post_init__(self) -> None:
        if self.kind not in ("ridge", "logistic"):
            raise ValueError(f"ProbeSettings.kind must be 'ridge' or 'logistic', got {self.kind!r}")
        check_protocol(self.protocol)

    @property
    def metric(self) -> str:
        return "r2" if self.kind == "ridge" else "accuracy"

    @property
    def draw_seed(self) -> int:
        """The seed of the bootstrap resamples and the controls' draws."""
        return self.seed if self.resample_seed is None else self.resample_seed

    @property
    def reg_name(self) -> str:
        if self.protocol == "mlp2":
            return "weight_decay"
        return "lambda" if self.kind == "ridge" else "C"

    @classmethod
    def from_config(
        cls, probes_cfg: Mapping, kind: str, seed: int, protocol: str = "raw"
    ) -> ProbeSettings:
        """Settings from the config section ``probes`` (validated by the schema); the ``mlp2``
        grid from ``probes.robustness.mlp`` when present."""
        return settings_from(
            cls,
            probes_cfg,
            where="probes",
            ignore=("families", "seeds", "fusions", "heads", "robustness"),
            kind=kind,
            seed=int(seed),
            protocol=check_protocol(protocol),
            mlp=MLPGrid.from_config((probes_cfg.get("robustness") or {}).get("mlp")),
        )


# --------------------------------------------------------------------------- rows + target


def target_values(frame: pd.DataFrame, target: str, kind: str) -> np.ndarray:
    """The probe target of each row: float for ridge, class labels (str) for logistic.

    ``log_mass`` is log(mass) (mass must be > 0). Missing labels come back as NaN (ridge) or
    None (logistic); `family_rows` drops those rows. A logistic class label is the value as
    text (``density`` 600.0 -> "600.0"), so numbers and words are treated alike.
    """
    source = "mass" if target == "log_mass" else target
    if source not in frame.columns:
        raise ValueError(
            f"target {target!r}: the manifest has no column {source!r} "
            f"(columns: {', '.join(sorted(map(str, frame.columns)))})"
        )
    col = frame[source]
    if kind == "ridge":
        values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64)
        if target == "log_mass":
            bad = values <= 0
            if bad.any():
                sid = frame["sample_id"].iloc[int(np.flatnonzero(bad)[0])]
                raise ValueError(f"target log_mass: sample_id {sid!r} has mass <= 0")
            values = np.log(values)
        return values
    labels = np.empty(len(col), dtype=object)
    for i, v in enumerate(col.tolist()):
        missing = v is None or (isinstance(v, float) and math.isnan(v))
        labels[i] = None if missing else str(v)
    return labels


@dataclass(frozen=True)
class FamilyRows:
    """The labelled train and test rows of one family, in sample_id order."""

    corpus: str
    target: str
    kind: str
    train_ids: np.ndarray
    test_ids: np.ndarray
    y_train: np.ndarray
    y_test: np.ndarray
    strata_test: np.ndarray | None  # bootstrap strata of the test rows (or None)
    bands_test: pd.DataFrame | None  # (low, high) band columns of the test rows (or None)
    n_unlabelled: int  # rows of the corpus dropped for a missing label
    strata_note: str = "none"  # how the bootstrap strata were formed (a summary column)
    visible_train: np.ndarray | None = None  # `visible_design` of the train rows (or None)
    visible_test: np.ndarray | None = None

    @property
    def n_train(self) -> int:
        return int(self.train_ids.size)

    @property
    def n_test(self) -> int:
        return int(self.test_ids.size)

    def train_test(self, edge, column: str) -> tuple[np.ndarray, np.ndarray]:
        """(train, test) arrays of one vector column of a verified edge
        (`tacgen_lib.io.edges.Edge`), rows in this family's sample_id order."""
        return (
            edge.subset(self.train_ids).vectors[column],
            edge.subset(self.test_ids).vectors[column],
        )


def strata_for(corpus: Mapping) -> tuple[str, ...] | None:
    """The bootstrap strata of a corpus's test rows (its config entry): the appearance-
    controlled design resamples within `CONTROLLED_STRATA`; any other corpus unstratified."""
    return CONTROLLED_STRATA if corpus.get("design") == "controlled" else None


def pool_strata(labels: np.ndarray, min_size: int = 2) -> tuple[np.ndarray, int]:
    """Bootstrap strata with at least `min_size` rows each: smaller cells are pooled.

    Resampling within a one-row cell always returns that row, which would shrink the CI for
    no reason; such rows are pooled into one stratum "pooled" (and if that pool is itself
    too small, the smallest remaining cells join it until it is not). Returns the labels and
    the number of pooled rows.
    """
    labels = np.asarray(labels, dtype=object).copy()
    counts = pd.Series(labels).value_counts()
    small = set(counts.index[counts < min_size])
    pooled = np.isin(labels, list(small))
    rest = counts[counts >= min_size].sort_values(kind="stable")
    for cell in rest.index:
        if pooled.sum() == 0 or pooled.sum() >= min_size:
            break
        pooled |= labels == cell
    labels[pooled] = "pooled"
    return labels, int(pooled.sum())


def family_rows(
    manifest: pd.DataFrame,
    splits: pd.DataFrame,
    *,
    corpus: str,
    target: str,
    kind: str,
    strata: Sequence[str] | None = None,
    within_scale: tuple[float, int] | None = None,
) -> FamilyRows:
    """Train (train + val) and test rows of `corpus` with their targets (sorted by sample_id).

    strata: manifest columns whose joint value defines bootstrap strata of the test rows
    (e.g. `CONTROLLED_STRATA`); None for unstratified resampling.
    within_scale: (test_fraction, seed) for the held-out-scale diagnosis: the train + val rows
    ONLY are re-split at random within each object scale (`subsets.within_scale_split`); the
    corpus's test rows are left out entirely (they never train anything).
    """
    rows = manifest.loc[manifest["corpus"] == corpus]
    if rows.empty:
        raise ValueError(f"corpus {corpus!r}: no rows in the manifest")
    rows = rows.merge(splits[["sample_id", "split"]], on="sample_id", how="left", validate="1:1")
    unsplit = rows["split"].isna()
    if unsplit.any():
        raise ValueError(
            f"corpus {corpus!r}: sample_id {rows.loc[unsplit, 'sample_id'].iloc[0]!r} "
            "is not in the split edge; rebuild the splits"
        )
    rows = rows.sort_values("sample_id", ignore_index=True)
    y = target_values(rows, target, kind)
    labelled = np.array([v is not None and v == v for v in y], dtype=bool)
    rows, y = rows.loc[labelled].reset_index(drop=True), y[labelled]
    train = rows["split"].isin(["train", "val"]).to_numpy()
    test = (rows["split"] == "test").to_numpy()
    if within_scale is not None:
        if "scale" not in rows.columns:
            raise ValueError(f"corpus {corpus!r}: within-scale split needs a 'scale' column")
        pool = np.flatnonzero(train)
        tr_i, te_i = within_scale_split(rows["scale"].to_numpy()[pool], *within_scale)
        train, test = np.zeros(len(rows), bool), np.zeros(len(rows), bool)
        train[pool[tr_i]], test[pool[te_i]] = True, True
    if not train.any() or not test.any():
        raise ValueError(
            f"corpus {corpus!r}, target {target!r}: {int(train.sum())} labelled train/val and "
            f"{int(test.sum())} labelled test rows; a probe needs both"
        )
    strata_test, strata_note = None, "none"
    if strata:
        missing = [c for c in strata if c not in rows.columns]
        if missing:
            raise ValueError(f"corpus {corpus!r}: no strata column(s) {missing} in the manifest")
        cells = rows.loc[test, list(strata)].astype(str).agg(" x ".join, axis=1)
        strata_test, n_pooled = pool_strata(cells.to_numpy(dtype=object))
        strata_note = f"{' x '.join(strata)}: {len(set(strata_test))} strata" + (
            f" ({n_pooled} test rows of cells with < 2 rows pooled)" if n_pooled else ""
        )
    bands_test = None
    if target in BANDS and all(c in rows.columns for c in BANDS[target]):
        bands_test = rows.loc[test, list(BANDS[target])].reset_index(drop=True).astype(float)
    ids = rows["sample_id"].to_numpy(dtype=object)
    visible = (None, None)
    if all(c in rows.columns for c in VISIBLE) and rows[list(VISIBLE)].notna().all().all():
        visible = visible_design(
            rows.loc[train], rows.loc[test], log_target=target.startswith("log_")
        )
    return FamilyRows(
        corpus=corpus,
        target=target,
        kind=kind,
        train_ids=ids[train],
        test_ids=ids[test],
        y_train=y[train],
        y_test=y[test],
        strata_test=strata_test,
        strata_note=strata_note,
        bands_test=bands_test,
        n_unlabelled=int((~labelled).sum()),
        visible_train=visible[0],
        visible_test=visible[1],
    )


#: Manifest columns of what vision can see of an object (the appearance-controlled design).
VISIBLE = ("shape", "scale")


def visible_design(
    train: pd.DataFrame, test: pd.DataFrame, *, log_target: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Design of the visible attributes shape and scale, for the shape-only ceiling.

    The best shape-only predictor of mass = density x c_shape x scale^3 (density unseen) is
    E[density] c_shape scale^3, linear in one-hot(shape) x scale^3; of log-mass
    (``log_target``) it is E[log density] + log c_shape + 3 log scale, linear in one-hot(shape)
    and log(scale). One form per target: the controlled split holds two training scales, on
    which scale^3 and log(scale) are collinear within a shape, so a design holding both would
    extrapolate to the test scale by an arbitrary mix of them. Columns are standardised with
    the TRAINING rows' mean and SD (a constant column is centred only); shapes are the union of
    both row sets' (a shape seen only in test has an all-zero training column).
    """
    shapes = sorted(set(train["shape"].astype(str)) | set(test["shape"].astype(str)))

    def design(frame: pd.DataFrame) -> np.ndarray:
        onehot = (frame["shape"].astype(str).to_numpy()[:, None] == np.array(shapes)).astype(float)
        scale = frame["scale"].to_numpy(dtype=np.float64)
        if log_target:
            return np.column_stack([onehot, np.log(scale)])
        return onehot * scale[:, None] ** 3

    x_tr, x_te = design(train), design(test)
    mu, sd = x_tr.mean(axis=0), x_tr.std(axis=0)
    sd = np.where(sd > 0, sd, 1.0)
    return (x_tr - mu) / sd, (x_te - mu) / sd


def baseline_score(y_train: np.ndarray, y_test: np.ndarray, metric: str) -> float:
    """Test score of the constant predictor fitted on the training rows: their mean (R^2) or
    their majority class (accuracy; ties to the first class in `class_order`)."""
    if metric == "r2":
        mean = float(np.mean(np.asarray(y_train, dtype=np.float64)))
        return score("r2", y_test, np.full(len(y_test), mean))
    labels = np.asarray(y_train, dtype=object)
    classes = class_order(labels)
    counts = [int(np.sum(labels == c)) for c in classes]
    majority = classes[int(np.argmax(counts))]
    return score("accuracy", np.asarray(y_test, dtype=object), np.full(len(y_test), majority))


def visible_score(rows: FamilyRows, settings: ProbeSettings) -> float:
    """Test score of the family's probe kind (regulariser by CV on the training rows) on the
    visible attributes (`visible_design`): the best a shape-only predictor attains, NaN when
    the manifest has no shape and scale."""
    if rows.visible_train is None:
        return math.nan
    try:
        fit = fit_probe(rows.visible_train, rows.y_train, rows.visible_test, settings)
    except ValueError:  # e.g. a class with one training row: no CV, no ceiling
        return math.nan
    return score(settings.metric, rows.y_test, fit.pred_test)


# --------------------------------------------------------------------------- probes


@dataclass(frozen=True)
class FittedProbe:
    """A probe fitted on the training rows: test predictions, chosen regulariser, diagnostics."""

    pred_test: np.ndarray
    reg: float  # lambda or C chosen by CV
    grid: np.ndarray
    cv_scores: np.ndarray  # mean held-out score per grid value
    converged: bool
    # most L-BFGS iterations of any of its fits (the CV's folds, batched where
    # `logistic.cv_batches`, and the final scikit-learn fit); None for ridge (closed form)
    n_iter: int | None
    pred_grid: np.ndarray | None = None  # (L, m) test predictions at every lambda (ridge)
    fixed_probe: FixedProbe | None = None  # set by protocols other than raw
    notes: str = ""  # what the protocol chose beyond `reg` (e.g. the MLP's width)

    def fixed(self, kind: str) -> FixedProbe:
        """The probe at its chosen regulariser, for controls and resampling diagnostics."""
        if self.fixed_probe is not None:
            return self.fixed_probe
        if kind == "ridge":
            return FixedRidge(self.reg)
        return FixedLogistic(self.reg, tol=CONTROL_TOL)


def fit_probe(
    X_train: np.ndarray,
    y_train: np.ndarray,
    X_test: np.ndarray,
    settings: ProbeSettings,
    *,
    train_ids: Sequence | np.ndarray | None = None,
    test_ids: Sequence | np.ndarray | None = None,
) -> FittedProbe:
    """Ridge (CV over ``lambdas``) or logistic (stratified CV over ``C``) on the training rows,
    under ``settings.protocol``: ``standardised`` ridge scales on the training rows first
    (`scaling`), ``mlp2`` fits the 2-layer probe (`mlp`); the logistic probe standardises
    under every protocol but ``mlp2``.

    The number of folds is capped at the number of training rows (ridge) or the smallest
    class count (logistic, inside `probes.fit_logistic`).
    """
    if settings.protocol == "mlp2":
        mlp = fit_mlp_probe(
            X_train, y_train, settings.kind, settings.mlp, settings.seed, sample_ids=train_ids
        )
        pred = mlp.predict(X_test, sample_ids=test_ids)
        if settings.kind == "logistic":
            pred = np.asarray(pred, dtype=object)
        return FittedProbe(
            pred,
            mlp.weight_decay,
            np.asarray(settings.mlp.weight_decays, dtype=np.float64),
            np.full(len(settings.mlp.weight_decays), np.nan),
            mlp.converged,
            mlp.n_iter,
            fixed_probe=FixedMLP(
                settings.kind, mlp.width, mlp.weight_decay, settings.seed, settings.mlp.max_iter
            ),
            notes=f"width {mlp.width}, weight decay {mlp.weight_decay:g}",
        )
    if settings.kind == "ridge" and settings.protocol == "standardised":
        sp = fit_standardised_ridge(
            X_train,
            y_train,
            settings.lambdas,
            n_folds=min(settings.folds, len(y_train)),
            seed=settings.seed,
            sample_ids=train_ids,
        )
        grid = sp.predict_grid(X_test, sample_ids=test_ids)
        return FittedProbe(
            grid[sp.best],
            sp.lam,
            sp.lambdas,
            sp.cv_scores,
            True,
            None,
            grid,
            fixed_probe=FixedStandardisedRidge(sp.lam),
        )
    if settings.kind == "ridge":
        probe = fit_ridge_probe(
            X_train,
            y_train,
            settings.lambdas,
            n_folds=min(settings.folds, len(y_train)),
            seed=settings.seed,
            sample_ids=train_ids,
        )
        sel = probe.selection
        pred = probe.predict(X_test, sample_ids=test_ids)
        grid = probe.predict_grid(X_test, sample_ids=test_ids)  # same decomposition as the CV
        return FittedProbe(pred, probe.lam, sel.lambdas, sel.cv_scores, True, None, grid)
    probe = fit_logistic(
        X_train, y_train, settings.C, settings.seed, n_folds=settings.folds, sample_ids=train_ids
    )
    pred = np.asarray(probe.predict(X_test, sample_ids=test_ids), dtype=object)
    return FittedProbe(
        pred,
        probe.C,
        probe.C_grid,
        probe.cv_scores,
        bool(probe.converged and probe.cv_converged),
        int(max(probe.n_iter, probe.cv_max_n_iter)),
    )


# --------------------------------------------------------------------------- plan


@dataclass(frozen=True)
class ComparisonSpec:
    """One V vs V+T comparison of a family: its input, tactile variant, fusion, seed."""

    input: str  # "raw" | "aligned"
    t_variant: str
    fusion: str
    align_seed: int | None
    controls: bool
    skip_reason: str | None = None


def plan_comparisons(
    fusions: Sequence[str],
    *,
    heads_variant: str,
    variants: Sequence[str],
    align_seeds: Sequence[int],
    dim_v_raw: int,
    dim_t_raw: int,
    control_align_seeds: int | None = None,
) -> list[ComparisonSpec]:
    """Every comparison of a family, in a fixed order (raw, tactile ablation, aligned).

    Controls run on ``concat`` of raw (heads' variant) and of aligned (every alignment seed,
    or only the first `control_align_seeds` in sorted order); when ``concat`` is not among the
    aligned fusions, on the first configured fusion instead.
    Same-dimension fusions on raw features of unequal dimension are planned as skipped rows.
    """
    unknown = [f for f in fusions if f not in FUSIONS]
    if unknown:
        raise ValueError(f"unknown fusion(s) {unknown}; choose from {sorted(FUSIONS)}")
    fusions = list(dict.fromkeys(fusions))
    raw_fusions = ["concat"] + [f for f in fusions if f != "concat"]
    control_aligned = "concat" if "concat" in fusions else fusions[0]
    plan = []
    for f in raw_fusions:
        reason = None
        if FUSIONS[f].same_dim and dim_v_raw != dim_t_raw:
            reason = (
                f"fusion {f!r} needs V and T of equal dimension; raw V has {dim_v_raw} and "
                f"raw T {dim_t_raw} (use the aligned input or concat)"
            )
        plan.append(ComparisonSpec("raw", heads_variant, f, None, f == "concat", reason))
    for v in variants:
        if v != heads_variant:
            plan.append(ComparisonSpec("raw", v, "concat", None, False))
    seeds = sorted(align_seeds)
    with_controls = set(seeds if control_align_seeds is None else seeds[:control_align_seeds])
    for s in seeds:
        for f in fusions:
            ctl = f == control_aligned and s in with_controls
            plan.append(ComparisonSpec("aligned", heads_variant, f, int(s), ctl))
    return plan


def row_id(
    family: str,
    spec: ComparisonSpec,
    probe_seed: int,
    control: str = "none",
    protocol: str = "raw",
) -> str:
    """The key of a result row (unique within a run); ``raw`` rows keep their older key."""
    a = "-" if spec.align_seed is None else str(spec.align_seed)
    p = "" if protocol == "raw" else f"p~{protocol}|"
    return (
        f"{family}|{spec.input}|t~{spec.t_variant}|{spec.fusion}|a~{a}|s~{probe_seed}|{p}{control}"
    )


def headline_plan(
    plan: Sequence[ComparisonSpec], heads_variant: str, *, controls: bool = True
) -> list[ComparisonSpec]:
    """The headline comparisons of a plan: ``concat`` with the heads' tactile variant (raw,
    and aligned per alignment seed), with controls only if `controls`."""
    return [
        replace(s, controls=s.controls and controls)
        for s in plan
        if s.fusion == "concat" and s.t_variant == heads_variant and s.skip_reason is None
    ]


# --------------------------------------------------------------------------- one comparison


@dataclass
class Comparison:
    """Outcome of one comparison: the main row, control rows, lambda sweep, predictions."""

    main: dict
    controls: list[dict] = field(default_factory=list)
    sweep: list[dict] = field(default_factory=list)
    pred_v: np.ndarray | None = None
    pred_vt: np.ndarray | None = None


def _control_row(name: str, out: dict) -> dict:
    """A control's distribution as a summary row: mean Delta, its 2.5/97.5% quantiles as the
    interval, the share of draws with Delta > 0. V is the V probe's score (mean over refits
    when the control refits it: training resamples, permuted labels)."""
    deltas = np.asarray(out["deltas"], dtype=np.float64)
    v = float(np.mean(out["v_scores"])) if "v_scores" in out else float(out["v_score"])
    n = int(deltas.size)
    return {
        "control": name,
        "status": "ok",
        "v_score": v,
        "vt_score": float(np.mean(out["vt_scores"])),
        "delta": float(out["delta_mean"]),
        "delta_sd": float(out["delta_sd"]),
        "ci_low": float(out["delta_q025"]),
        "ci_high": float(out["delta_q975"]),
        "p_gt0": float(np.mean(deltas > 0.0)),
        "n_resamples": n,
    }


def compare(
    v_train: np.ndarray,
    v_test: np.ndarray,
    t_train: np.ndarray,
    t_test: np.ndarray,
    rows: FamilyRows,
    fusion: str,
    settings: ProbeSettings,
    *,
    controls: bool,
    v_probe: FittedProbe | None = None,
) -> Comparison:
    """V vs fuse(V, T) on the family's rows: fit, bootstrap, (controls), criterion, sweep.

    v_probe: the V probe fitted on (v_train, y_train), shared between the comparisons of one
    input (it does not depend on T or the fusion). Controls refit at the CV-chosen
    regularisers. Returns the main row (statistics and diagnostics) and, with controls, one
    row per control in `CONTROLS`; seeds are all ``settings.draw_seed``, so every comparison of a
    family sees the same bootstrap resamples and permutations (paired across comparisons).
    """
    kind, metric = settings.kind, settings.metric
    y_tr, y_te = rows.y_train, rows.y_test
    x_vt_tr, x_vt_te = fuse(fusion, v_train, t_train), fuse(fusion, v_test, t_test)
    if v_probe is None:
        v_probe = fit_probe(
            v_train, y_tr, v_test, settings, train_ids=rows.train_ids, test_ids=rows.test_ids
        )
    vt_probe = fit_probe(
        x_vt_tr, y_tr, x_vt_te, settings, train_ids=rows.train_ids, test_ids=rows.test_ids
    )
    boot = fixed_test_bootstrap(
        y_te,
        v_probe.pred_test,
        vt_probe.pred_test,
        metric,
        n_resamples=settings.bootstrap,
        seed=settings.draw_seed,
        strata=rows.strata_test,
        sample_ids=rows.test_ids,
    )
    main = {
        "control": "none",
        "status": "ok",
        "v_score": boot["v_score"],
        "vt_score": boot["vt_score"],
        "delta": boot["delta"],
        "delta_sd": math.nan,
        "ci_low": boot["ci_low"],
        "ci_high": boot["ci_high"],
        "p_gt0": boot["p_gt0"],
        "n_resamples": boot["n_resamples"],
        "n_constant_resamples": boot["n_constant_resamples"],
        "v_reg": v_probe.reg,
        "vt_reg": vt_probe.reg,
        "dim_v": int(v_train.shape[1]),
        "dim_vt": int(x_vt_tr.shape[1]),
        "converged": bool(v_probe.converged and vt_probe.converged),
        "n_iter_v": v_probe.n_iter,
        "n_iter_vt": vt_probe.n_iter,
        "controls": "run" if controls else "not run",
        "delta_ctrl": math.nan,
        "criterion_met": None,
        "notes": "",
    }
    chosen = "; ".join(f"{m}: {p.notes}" for m, p in (("V", v_probe), ("V+T", vt_probe)) if p.notes)
    if rows.bands_test is not None:
        lo, hi = (rows.bands_test[c].to_numpy() for c in rows.bands_test.columns)
        main["band_low_mean"] = float(np.mean(lo))
        main["band_high_mean"] = float(np.mean(hi))
        main["v_in_band"] = float(np.mean((v_probe.pred_test >= lo) & (v_probe.pred_test <= hi)))
        main["vt_in_band"] = float(np.mean((vt_probe.pred_test >= lo) & (vt_probe.pred_test <= hi)))
    result = Comparison(main, pred_v=v_probe.pred_test, pred_vt=vt_probe.pred_test)
    test_v = test_vt = np.full(v_probe.grid.size, np.nan)
    if kind == "ridge" and v_probe.pred_grid is not None and vt_probe.pred_grid is not None:
        test_v = np.array([score("r2", y_te, p) for p in v_probe.pred_grid])
        test_vt = np.array([score("r2", y_te, p) for p in vt_probe.pred_grid])
    # the mlp2 grid is 2-D (width x weight decay): its choice is in the notes, not the sweep
    for i, reg in enumerate(v_probe.grid if settings.protocol != "mlp2" else []):
        result.sweep.append(
            {
                "reg": float(reg),
                "cv_v": float(v_probe.cv_scores[i]),
                "cv_vt": float(vt_probe.cv_scores[i]),
                "test_v": float(test_v[i]),
                "test_vt": float(test_vt[i]),
                "delta_test": float(test_vt[i] - test_v[i]),
                "selected_v": bool(reg == v_probe.reg),
                "selected_vt": bool(reg == vt_probe.reg),
            }
        )
    if not controls:
        main["notes"] = "; ".join(
            x
            for x in (
                "controls not run (see the plan: concat comparisons only, and none "
                "under a protocol variant in the default budget)",
                chosen,
            )
            if x
        )
        return result
    fixed_v, fixed_vt = v_probe.fixed(kind), vt_probe.fixed(kind)
    common = {"metric": metric, "seed": settings.draw_seed}
    paired = PairedRows(v_train, t_train, y_tr, v_test, t_test, y_te, fusion)
    runs = {
        "train_resample": (
            settings.train_resamples,
            lambda: train_resample_diagnostic(
                paired,
                probe_v=fixed_v,
                probe_vt=fixed_vt,
                n_resamples=settings.train_resamples,
                **common,
            ),
        ),
        "tactile_permutation": (
            settings.permutations,
            lambda: tactile_permutation_control(
                paired,
                probe=fixed_vt,
                probe_v=fixed_v,
                n_permutations=settings.permutations,
                **common,
            ),
        ),
        "label_permutation": (
            settings.label_permutations,
            lambda: label_permutation_control(
                paired,
                probe_v=fixed_v,
                probe_vt=fixed_vt,
                n_permutations=settings.label_permutations,
                **common,
            ),
        ),
        "random_features": (
            settings.random_draws,
            lambda: random_feature_control(
                paired,
                probe=fixed_vt,
                probe_v=fixed_v,
                n_draws=settings.random_draws,
                **common,
            ),
        ),
    }
    for name in CONTROLS:
        count, call = runs[name]
        if count <= 0:
            continue
        with warnings.catch_warnings(record=True) as caught:
            # A logistic refit that misses convergence at the iteration cap warns once per
            # refit; the warnings are counted into the control's notes, not flooded to the log.
            warnings.simplefilter("always", category=ConvergenceWarning)
            try:
                row = _control_row(name, call())
            except ValueError as exc:  # e.g. a training resample left holding one class
                row = {"control": name, "status": "failed", "notes": f"control failed: {exc}"}
        for w in caught:
            if not issubclass(w.category, ConvergenceWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        unconverged = sum(issubclass(w.category, ConvergenceWarning) for w in caught)
        if unconverged:
            row["notes"] = f"{unconverged} refit(s) did not converge within the iteration cap"
        result.controls.append(row)
        if name == "tactile_permutation" and row.get("status", "ok") == "ok":
            main["delta_ctrl"] = row["delta"]
    main["notes"] = chosen
    if math.isnan(main["delta_ctrl"]):
        main["notes"] = "no tactile-permutation control (probes.permutations = 0, or it failed)"
    else:
        main["criterion_met"] = paper_criterion(
            main["delta"], main["ci_low"], main["delta_ctrl"], settings.min_delta
        )
    return result


def confusion_counts(
    y_true: np.ndarray, y_pred: np.ndarray, classes: Sequence[str]
) -> list[tuple[str, str, int]]:
    """(true, predicted, count) for every pair of classes, zeros included."""
    y_true, y_pred = np.asarray(y_true, dtype=object), np.asarray(y_pred, dtype=object)
    return [(a, b, int(np.sum((y_true == a) & (y_pred == b)))) for a in classes for b in classes]


# --------------------------------------------------------------------------- a family


@dataclass(frozen=True)
class FamilyResult:
    """Tidy tables of one family and probe seed: results, lambda/C sweep, confusion counts."""

    rows: pd.DataFrame
    sweep: pd.DataFrame
    confusion: pd.DataFrame


def run_family(
    family: str,
    rows: FamilyRows,
    *,
    vision: tuple[np.ndarray, np.ndarray],
    tactile: Mapping[str, tuple[np.ndarray, np.ndarray]],
    aligned: Mapping[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    fusions: Sequence[str],
    heads_variant: str,
    settings: ProbeSettings,
    labels: Mapping[str, object] | None = None,
    progress: Callable[[str], None] | None = None,
    headline_only: bool = False,
    controls: bool = True,
) -> FamilyResult:
    """Run every planned comparison of one family and probe seed.

    headline_only: only the `headline_plan` comparisons; controls: False leaves every control
    out (the bootstrap CI stays). Both serve the protocol variants' budget.

    vision: raw V features (train rows, test rows), rows in ``rows.train_ids`` /
        ``rows.test_ids`` order; tactile: variant -> raw T features (train, test);
    aligned: alignment seed -> (V_aligned train, V_aligned test, T_aligned train, test).
    labels: constant columns added to every row (e.g. corpus design, vision feature kind).
    A comparison whose probe cannot be fitted (e.g. a class with a single training row) is a
    ``failed`` row with the error as its note; a planned skip is a ``skipped`` row.
    """
    say = progress or (lambda _msg: None)
    if heads_variant not in tactile:
        raise ValueError(
            f"family {family!r}: no raw tactile features for the heads' variant {heads_variant!r}"
        )
    v_tr, v_te = vision
    plan = plan_comparisons(
        fusions,
        heads_variant=heads_variant,
        variants=list(tactile),
        align_seeds=sorted(aligned),
        dim_v_raw=v_tr.shape[1],
        dim_t_raw=tactile[heads_variant][0].shape[1],
        control_align_seeds=None if settings.kind == "ridge" else LOGISTIC_CONTROL_ALIGN_SEEDS,
    )
    if headline_only:
        plan = headline_plan(plan, heads_variant, controls=controls)
    elif not controls:
        plan = [replace(s, controls=False) for s in plan]
    base = {
        "family": family,
        "corpus": rows.corpus,
        "target": rows.target,
        "kind": settings.kind,
        "metric": settings.metric,
        "reg_name": settings.reg_name,
        "probe_seed": settings.seed,
        "protocol": settings.protocol,
        "heads_variant": heads_variant,
        "n_train": rows.n_train,
        "n_test": rows.n_test,
        "n_unlabelled": rows.n_unlabelled,
        "bootstrap_strata": rows.strata_note,
        "baseline_score": baseline_score(rows.y_train, rows.y_test, settings.metric),
        "visible_score": visible_score(rows, settings),
        **(labels or {}),
    }
    classes = class_order([*rows.y_train, *rows.y_test]) if settings.kind == "logistic" else []
    out_rows, sweep_rows, conf_rows = [], [], []
    v_cache: dict[tuple, FittedProbe] = {}
    for i, spec in enumerate(plan):
        ident = {
            "input": spec.input,
            "t_variant": spec.t_variant,
            "fusion": spec.fusion,
            "align_seed": spec.align_seed,
        }
        key = row_id(family, spec, settings.seed, protocol=settings.protocol)
        if spec.skip_reason is not None:
            out_rows.append(
                {
                    "row_id": key,
                    **base,
                    **ident,
                    "control": "none",
                    "status": "skipped",
                    "controls": "not run",
                    "notes": spec.skip_reason,
                }
            )
            continue
        if spec.input == "raw":
            vv_tr, vv_te = v_tr, v_te
            tt_tr, tt_te = tactile[spec.t_variant]
            cache_key = ("raw",)
        else:
            vv_tr, vv_te, tt_tr, tt_te = aligned[spec.align_seed]
            cache_key = ("aligned", spec.align_seed)
        try:
            if cache_key not in v_cache:
                v_cache[cache_key] = fit_probe(
                    vv_tr,
                    rows.y_train,
                    vv_te,
                    settings,
                    train_ids=rows.train_ids,
                    test_ids=rows.test_ids,
                )
            res = compare(
                vv_tr,
                vv_te,
                tt_tr,
                tt_te,
                rows,
                spec.fusion,
                settings,
                controls=spec.controls,
                v_probe=v_cache[cache_key],
            )
        except ValueError as exc:
            out_rows.append(
                {
                    "row_id": key,
                    **base,
                    **ident,
                    "control": "none",
                    "status": "failed",
                    "controls": "not run",
                    "notes": f"probe could not be fitted: {exc}",
                }
            )
            say(f"[{i + 1}/{len(plan)}] {key}: failed ({exc})")
            continue
        out_rows.append({"row_id": key, **base, **ident, **res.main})
        for c in res.controls:
            out_rows.append(
                {
                    "row_id": row_id(family, spec, settings.seed, c["control"], settings.protocol),
                    **base,
                    **ident,
                    "controls": "run",
                    **c,
                }
            )
        for s in res.sweep:
            sweep_rows.append(
                {
                    "row_id": f"{key}|{settings.reg_name}={s['reg']:g}",
                    "comparison": key,
                    "family": family,
                    "corpus": rows.corpus,
                    "target": rows.target,
                    "metric": settings.metric,
                    **ident,
                    "probe_seed": settings.seed,
                    "protocol": settings.protocol,
                    "heads_variant": heads_variant,
                    "reg_name": settings.reg_name,
                    **s,
                }
            )
        if settings.kind == "logistic":
            for model, pred in (("V", res.pred_v), ("V+T", res.pred_vt)):
                for a, b, n in confusion_counts(rows.y_test, pred, classes):
                    conf_rows.append(
                        {
                            "row_id": f"{key}|{model}|{a}|{b}",
                            "comparison": key,
                            "family": family,
                            "corpus": rows.corpus,
                            "target": rows.target,
                            **ident,
                            "probe_seed": settings.seed,
                            "protocol": settings.protocol,
                            "heads_variant": heads_variant,
                            "model": model,
                            "true": a,
                            "pred": b,
                            "count": n,
                        }
                    )
        say(
            f"[{i + 1}/{len(plan)}] {key}: V {res.main['v_score']:.3f} V+T "
            f"{res.main['vt_score']:.3f} delta {res.main['delta']:+.3f} "
            f"[{res.main['ci_low']:+.3f}, {res.main['ci_high']:+.3f}]"
        )
    return FamilyResult(
        rows=tidy(pd.DataFrame(out_rows)),
        sweep=tidy(_frame(sweep_rows, SWEEP_COLUMNS)),
        confusion=tidy(_frame(conf_rows, CONFUSION_COLUMNS)),
    )


_IDENT = {
    "row_id": "str",
    "comparison": "str",
    "family": "str",
    "corpus": "str",
    "target": "str",
    "input": "str",
    "t_variant": "str",
    "fusion": "str",
    "align_seed": "Int64",
    "probe_seed": "int64",
    "protocol": "str",
    "heads_variant": "str",
}
#: Columns of the lambda/C sweep table (one row per comparison and regulariser value).
SWEEP_COLUMNS = {
    **_IDENT,
    "metric": "str",
    "reg_name": "str",
    "reg": "float64",
    "cv_v": "float64",
    "cv_vt": "float64",
    "test_v": "float64",
    "test_vt": "float64",
    "delta_test": "float64",
    "selected_v": "bool",
    "selected_vt": "bool",
}
#: Columns of the confusion-count table (logistic families; empty for ridge families).
CONFUSION_COLUMNS = {**_IDENT, "model": "str", "true": "str", "pred": "str", "count": "int64"}


def _frame(rows: list[dict], columns: Mapping[str, str]) -> pd.DataFrame:
    """Rows as a frame with exactly `columns`, typed even when there are no rows."""
    frame = pd.DataFrame(rows, columns=list(columns))
    if frame.empty:
        return frame.astype(dict(columns))
    return frame


_INT_COLUMNS = (
    "align_seed",
    "n_iter_v",
    "n_iter_vt",
    "n_resamples",
    "n_constant_resamples",
    "dim_v",
    "dim_vt",
)


def tidy(frame: pd.DataFrame) -> pd.DataFrame:
    """Stable column types for Parquet (and after reading one back): nullable ints for seeds,
    iterations, counts and dimensions; nullable booleans for the criterion and convergence."""
    frame = frame.copy()
    for col in _INT_COLUMNS:
        if col in frame.columns:
            frame[col] = pd.array(
                [None if pd.isna(v) else int(v) for v in frame[col]], dtype="Int64"
            )
    for col in ("criterion_met", "converged"):
        if col in frame.columns:
            frame[col] = pd.array(
                [None if pd.isna(v) else bool(v) for v in frame[col]], dtype="boolean"
            )
    if "notes" in frame.columns:
        frame["notes"] = frame["notes"].fillna("").astype(str)
    return frame


def class_order(labels: Sequence) -> list[str]:
    """Distinct class labels in natural order: numerically when every label is a number
    ("500.0" < "2000.0"), else alphabetically."""
    distinct = sorted({str(x) for x in labels})
    try:
        return sorted(distinct, key=float)
    except ValueError:
        return distinct
