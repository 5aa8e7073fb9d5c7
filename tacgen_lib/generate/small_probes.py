"""Probes on few labelled rows: the probes stage's probe, and the nonlinear V baseline's, with
the cases cross-validation cannot handle made explicit; and the exact RBF-kernel probe, the
best probe on V with every label.

The regime (`tacgen_lib.generate.regime`) fits the first two on labelled sets as small as a
few rows. The kernel probe (`fit_kernel_probe`) is the visibility check's nonlinear probe
(`tacgen_lib.generate.visibility`) and the regime's V ceiling, both on every non-test row of a
corpus: there the nonlinear baseline's Nystroem map, of rank the feature width, is a
low-rank view of the kernel that the exact one outscores.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tacgen_lib.generate.baselines import (
    median_sq_distance,
    nonlinear_baseline,
    nystroem_ridge,
    standardise,
)
from tacgen_lib.probes.fit import fit_probe
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.settings import MLPGrid, ProbeSettings

__all__ = [
    "SmallFit",
    "fit_kernel_probe",
    "fit_small_mlp",
    "fit_small_nonlinear",
    "fit_small_probe",
]


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


def fit_small_nonlinear(
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


def fit_small_mlp(
    x_train: np.ndarray,
    y_train: np.ndarray,
    x_test: np.ndarray,
    settings: ProbeSettings,
    grid: MLPGrid,
) -> SmallFit:
    """The probes stage's 2-layer probe (`fit_mlp_probe`: width and weight decay by stratified
    CV over `grid`, seeded by ``settings.seed``) on a logistic family's labels, or the
    `fit_small_probe` fallback where CV cannot run on these labels (`_cv_impossible`).
    SmallFit.reg is the chosen weight decay."""
    y = np.asarray(y_train)
    if _cv_impossible(y, settings):
        return fit_small_probe(x_train, y, x_test, settings)
    from tacgen_lib.probes.mlp import fit_mlp_probe  # scikit-learn: only where fitted

    fit = fit_mlp_probe(x_train, y, settings.kind, grid, settings.seed)
    return SmallFit(np.asarray(fit.predict(x_test), dtype=object), fit.weight_decay, "cv")


def fit_kernel_probe(
    x_train: np.ndarray,
    y_train: np.ndarray,
    x_test: np.ndarray,
    settings: ProbeSettings,
    *,
    gammas: Sequence[float],
    C: Sequence[float],
    large: tuple[int, int] | None = None,
) -> SmallFit:
    """The exact RBF-kernel probe on standardised features (the train rows' mean and std): a
    logistic family's labels by a support-vector classifier (scikit-learn ``SVC``, one-vs-one,
    penalty ``C``), a ridge family's by kernel ridge (``KernelRidge``, penalty among the
    family's lambdas). gamma = multiple / `median_sq_distance` of the train rows, the multiple
    among `gammas`; (penalty, multiple) by the mean held-out score (`metrics.score`: accuracy;
    R^2 for ridge) over the family's folds (`make_folds`: stratified for a logistic family,
    seeded by ``settings.seed``, ``settings.cv_repeats`` draws), the first of the grid's order
    on ties (penalties ascending, then multiples ascending: the smoother fit). Refitted on
    every train row. Deterministic: the solvers draw no random numbers.

    `large` = (rows, rank) bounds the cost on more train rows than ``rows`` (the regime's V
    ceiling on a large corpus): kernel ridge's exact solve grows as the cube of the rows, so a
    ridge family's probe is then ridge without intercept on ``rank`` RBF Nystroem features
    (scikit-learn's ``Nystroem``, landmark rows drawn with ``settings.seed``, the same gamma):
    kernel ridge with that low-rank kernel, the same penalty meaning the same (as the regime's
    kernel ridge rung, `generate.kernel_ridge_generator`). The SVM stays exact, but each of its
    CV fits grows as the square of the rows or worse (a large C on labels V barely reads
    converges slowly), so its grid is chosen by CV on a stratified draw of ``rows`` train rows
    (seeded by ``settings.seed``) and the chosen SVM refitted on every train row.

    Where CV cannot run on these labels (`_cv_impossible`) it is `fit_small_probe`'s fallback.
    SmallFit.reg is the chosen C (or lambda), gamma_multiple the chosen multiple, source
    ``cv``, ``cv, Nystroem rank R`` on Nystroem features, ``cv on R of N rows`` for an SVM
    whose grid a draw of rows chose.
    """
    from sklearn.kernel_ridge import KernelRidge  # scikit-learn: only where fitted
    from sklearn.svm import SVC

    y = np.asarray(y_train)
    if _cv_impossible(y, settings):
        return fit_small_probe(x_train, y, x_test, settings)
    z_tr, z_te = standardise(np.asarray(x_train, np.float64), np.asarray(x_test, np.float64))
    med = median_sq_distance(z_tr)
    logistic = settings.kind == "logistic"
    penalties = sorted(float(c) for c in (C if logistic else settings.lambdas))
    multiples = sorted(float(g) for g in gammas)
    labels = y.astype(str) if logistic else None
    y_fit = labels if logistic else y.astype(np.float64)
    metric = "accuracy" if logistic else "r2"
    is_large = large is not None and len(y) > int(large[0])
    rank = min(int(large[1]), len(y)) if is_large and not logistic else 0
    cv_rows = _cv_draw(labels, int(large[0]), settings.seed) if is_large and logistic else None
    splits = _cv_splits(len(y), settings, labels, cv_rows)
    source = "cv"
    if rank:
        source = f"cv, Nystroem rank {rank}"
    elif cv_rows is not None:
        source = f"cv on {len(cv_rows)} of {len(y)} rows"

    def model(pen: float, mult: float):
        if logistic:
            return SVC(C=pen, kernel="rbf", gamma=mult / med)
        if rank:
            return nystroem_ridge(mult / med, pen, rank=rank, seed=settings.seed)
        return KernelRidge(alpha=pen, kernel="rbf", gamma=mult / med)

    def held_out(pen: float, mult: float) -> float:
        scores = []
        for tr, ho in splits:
            pred = model(pen, mult).fit(z_tr[tr], y_fit[tr]).predict(z_tr[ho])
            scores.append(score(metric, y_fit[ho], pred))
        return float(np.mean(scores))

    grid = [(pen, mult) for pen in penalties for mult in multiples]
    cv = [held_out(pen, mult) for pen, mult in grid]
    pen, mult = grid[int(np.argmax(cv))]  # the first maximum: the grid's order
    pred = model(pen, mult).fit(z_tr, y_fit).predict(z_te)
    pred = np.asarray(pred, dtype=object if logistic else np.float64)
    return SmallFit(pred, pen, source, mult)


def _cv_draw(labels: np.ndarray, rows: int, seed: int) -> np.ndarray:
    """A stratified draw of `rows` of the rows of `labels` (scikit-learn's
    ``train_test_split``, seeded), in row order: the rows a large SVM's grid is chosen on."""
    from sklearn.model_selection import train_test_split

    drawn, _ = train_test_split(
        np.arange(len(labels)), train_size=rows, stratify=labels, random_state=seed
    )
    return np.sort(drawn)


def _cv_splits(
    n: int, settings: ProbeSettings, labels: np.ndarray | None, rows: np.ndarray | None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(fit rows, held-out rows) of the kernel probe's CV: the family's folds (`make_folds`)
    of every one of the `n` rows, or of `rows` only where given (indices into the n)."""
    idx = np.arange(n) if rows is None else rows
    folds = make_folds(
        len(idx),
        settings.folds,
        settings.seed,
        labels=None if labels is None else labels[idx],
        repeats=settings.cv_repeats,
    )
    every = np.arange(len(idx))
    return [(idx[np.setdiff1d(every, ho, assume_unique=True)], idx[ho]) for ho in folds]
