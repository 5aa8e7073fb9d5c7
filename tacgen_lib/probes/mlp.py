"""The ``mlp2`` probe protocol: a 2-layer probe (one hidden ReLU layer), seeded.

The paper reports that 2-layer probes keep the direction of its linear probes. This module
owns that probe, built from scikit-learn's ``MLPRegressor`` / ``MLPClassifier`` (lbfgs: at
probe sizes, a few hundred rows, it is the deterministic and fast solver):

- `mlp_model`: the estimator of one grid point: features standardised on the fit's training
  rows; for regression the target is standardised too (``TransformedTargetRegressor``), so one
  weight-decay grid serves targets of any unit; weights initialised from ``random_state=seed``.
- `fit_mlp_probe` / `MLPProbe`: hidden width and weight decay (scikit-learn's ``alpha``) chosen
  by K-fold CV on the TRAINING rows (plain folds for regression, stratified for classes, as
  the linear probes; mean held-out R^2 or accuracy; first best in (weight decay, width) order,
  the order of ``GridSearchCV``'s parameter grid), then refitted on every training row.
- `FixedMLP`: the probe at its chosen width and weight decay for controls (`refits.Refits`):
  one refit at a time (an MLP has no batched solver here).

Convergence is recorded, not assumed: a fit that stops at ``max_iter`` counts as unconverged
and its ConvergenceWarning is swallowed into that flag (the probe row says so).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.compose import TransformedTargetRegressor
from sklearn.exceptions import ConvergenceWarning
from sklearn.neural_network import MLPClassifier, MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tacgen_lib.probes.blas_threads import single_blas_thread
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.input_checks import check_features, check_target
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.refits import Refits, Refitted
from tacgen_lib.probes.settings import MLPGrid

__all__ = ["FixedMLP", "MLPGrid", "MLPProbe", "fit_mlp_probe", "mlp_model"]


def mlp_model(
    kind: str, width: int, weight_decay: float, seed: int, max_iter: int
) -> BaseEstimator:
    """The scikit-learn estimator of one grid point (kind "ridge": regression, else classes)."""
    common = {
        "hidden_layer_sizes": (int(width),),
        "alpha": float(weight_decay),
        "solver": "lbfgs",
        "max_iter": int(max_iter),
        "random_state": int(seed),
    }
    if kind == "ridge":
        return TransformedTargetRegressor(
            regressor=make_pipeline(StandardScaler(), MLPRegressor(**common)),
            transformer=StandardScaler(),
        )
    return make_pipeline(StandardScaler(), MLPClassifier(**common))


def _fit(model: BaseEstimator, X: np.ndarray, y: np.ndarray) -> tuple[BaseEstimator, bool]:
    """Fit `model`; (model, converged). Other warnings than ConvergenceWarning pass through."""
    with warnings.catch_warnings(record=True) as caught, single_blas_thread():
        warnings.simplefilter("always")
        model.fit(X, y)
    unconverged = False
    for w in caught:
        if issubclass(w.category, ConvergenceWarning):
            unconverged = True
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return model, not unconverged


@dataclass(frozen=True)
class MLPProbe:
    """A 2-layer probe: CV-chosen width and weight decay, refitted on all training rows."""

    width: int
    weight_decay: float
    grid: MLPGrid
    cv_scores: np.ndarray  # (len(grid.points),) mean held-out score, grid.points order
    model: BaseEstimator = field(repr=False)
    converged: bool  # the refit and every CV fit
    n_iter: int

    def predict(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        return self.model.predict(check_features(X, name="X_test", sample_ids=sample_ids))


def _n_iter(model: BaseEstimator) -> int:
    est = model.regressor_ if isinstance(model, TransformedTargetRegressor) else model
    return int(est[-1].n_iter_)


def fit_mlp_probe(
    X_train: np.ndarray,
    y_train: np.ndarray,
    kind: str,
    grid: MLPGrid,
    seed: int,
    *,
    sample_ids: Sequence | np.ndarray | None = None,
) -> MLPProbe:
    """Width and weight decay by K-fold CV on the training rows, then the refit on all of them.

    Pass only TRAINING rows. kind "ridge" scores R^2 on plain folds; "logistic" scores
    accuracy on stratified folds (capped at the smallest class count). Every fit is seeded
    with `seed`, so the result is reproducible.
    """
    X = check_features(X_train, sample_ids=sample_ids)
    numeric = kind == "ridge"
    y = check_target(y_train, X.shape[0], sample_ids=sample_ids, numeric=numeric)
    if numeric:
        folds = make_folds(X.shape[0], min(grid.folds, X.shape[0]), seed)
        metric = "r2"
    else:
        classes, counts = np.unique(y, return_counts=True)
        k = int(min(grid.folds, counts.min()))
        if classes.size < 2 or k < 2:
            raise ValueError(
                f"fit_mlp_probe: training classes {dict(zip(classes, counts, strict=True))}; "
                "stratified CV needs two classes with at least 2 rows each"
            )
        folds = make_folds(X.shape[0], k, seed, labels=y)
        metric = "accuracy"
    points = grid.points
    scores = np.zeros((len(folds), len(points)))
    all_converged = True
    for f, ho in enumerate(folds):
        tr = np.setdiff1d(np.arange(X.shape[0]), ho, assume_unique=True)
        for j, (wd, width) in enumerate(points):
            model, ok = _fit(mlp_model(kind, width, wd, seed, grid.max_iter), X[tr], y[tr])
            all_converged &= ok
            scores[f, j] = score(metric, y[ho], model.predict(X[ho]))
    cv = scores.mean(axis=0)
    wd, width = points[int(np.argmax(cv))]
    model, ok = _fit(mlp_model(kind, width, wd, seed, grid.max_iter), X, y)
    return MLPProbe(
        int(width), float(wd), grid, cv, model, bool(ok and all_converged), _n_iter(model)
    )


@dataclass(frozen=True)
class FixedMLP:
    """The 2-layer probe at a fixed width and weight decay, for controls."""

    kind: str
    width: int
    weight_decay: float
    seed: int
    max_iter: int

    def fit_predict(self, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray):
        model = mlp_model(self.kind, self.width, self.weight_decay, self.seed, self.max_iter)
        model, _ = _fit(model, np.asarray(X_train, np.float64), np.asarray(y_train))
        return model.predict(np.asarray(X_test, np.float64))

    def batches(self, refits: Refits) -> bool:
        """Never: every refit is its own scikit-learn fit."""
        return False

    def refit_many(self, refits: Refits, *, batched: bool | None = None) -> Refitted:
        """(B, m) test predictions, one refit per problem."""
        return Refitted(refits.loop(self.fit_predict), {"refits": refits.n_problems})
