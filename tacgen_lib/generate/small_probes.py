"""Probes on few labelled rows: the probes stage's probe, and the nonlinear V baseline's, with
the cases cross-validation cannot handle made explicit.

The regime (`tacgen_lib.generate.regime`) fits them on labelled sets as small as a few rows;
the visibility check (`tacgen_lib.generate.visibility`) on every non-test row of a corpus.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tacgen_lib.generate.baselines import nonlinear_baseline
from tacgen_lib.probes.fit import fit_probe
from tacgen_lib.probes.settings import ProbeSettings

__all__ = ["SmallFit", "fit_small_probe", "fit_small_nonlinear"]


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
