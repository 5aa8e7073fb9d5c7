"""The ``standardised`` probe protocol for ridge: per-feature scaling fitted on training rows.

A reviewer's first change to a ridge probe is ``make_pipeline(StandardScaler(), Ridge())``.
This module owns that probe: every fit (each CV fold, the refit, each refit of a control)
fits its scaler on ITS OWN training rows only -- the fold's held-out rows and the test rows
never move a mean or an SD -- and then solves the ridge of `ridge` on the scaled columns.

- `fit_standardised_ridge` / `StandardisedRidgeProbe`: lambda by K-fold CV on the training rows
  (the folds of `folds.make_folds`, mean held-out R^2, first best in grid order), equal to
  ``GridSearchCV(make_pipeline(StandardScaler(), Ridge()), cv=<same folds>)``.
- `FixedStandardisedRidge`: the probe at its chosen lambda for controls (`refits.Refits`):
  B permuted targets of one design share one scaler and one factorisation; anything else is
  one scaled refit at a time.

Logistic probes need no twin: `logistic.fit_logistic` has standardised inside every fit
since it was written, so for them ``standardised`` is ``raw`` (see `protocol_variants.PROTOCOLS`).
A zero-variance column is centred only (scale 1), as scikit-learn's scaler does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from sklearn.preprocessing import StandardScaler

from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.input_checks import check_features, check_lambdas, check_target
from tacgen_lib.probes.metrics import score_rows
from tacgen_lib.probes.refits import Refits, Refitted
from tacgen_lib.probes.ridge_cv import LambdaCV
from tacgen_lib.probes.ridge_path import RidgePath, ridge_fixed, ridge_path

__all__ = ["FixedStandardisedRidge", "StandardisedRidgeProbe", "fit_standardised_ridge"]


def _scaler(X: np.ndarray) -> StandardScaler:
    """A StandardScaler fitted on the rows of X (training rows only)."""
    return StandardScaler().fit(np.asarray(X, dtype=np.float64))


@dataclass(frozen=True)
class StandardisedRidgeProbe(LambdaCV):
    """The CV's choice (`LambdaCV`), the scaler fitted on all training rows and the ridge path
    on the scaled columns."""

    scaler: StandardScaler = field(repr=False)
    path: RidgePath = field(repr=False)

    def predict_grid(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        """(L, m) test predictions of the refit at every lambda of the grid."""
        X = check_features(X, name="X_test", sample_ids=sample_ids)
        return self.path.predict(self.scaler.transform(X))

    def predict(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        return self.predict_grid(X, sample_ids=sample_ids)[self.best]


def fit_standardised_ridge(
    X_train: np.ndarray,
    y_train: np.ndarray,
    lambdas: Sequence[float] | np.ndarray,
    *,
    n_folds: int,
    seed: int,
    repeats: int,
    sample_ids: Sequence | np.ndarray | None = None,
) -> StandardisedRidgeProbe:
    """StandardScaler + ridge, lambda by K-fold CV on the training rows (pass only those).

    In each fold the scaler is fitted on the fold's training rows, so a held-out row never
    shapes the scaling that scores it; the refit's scaler sees every training row and no test
    row. Folds are `make_folds(n, n_folds, seed, repeats=repeats)`, the raw ridge probe's.
    """
    X = check_features(X_train, sample_ids=sample_ids)
    y = check_target(y_train, X.shape[0], sample_ids=sample_ids)
    lam = check_lambdas(lambdas)
    folds = make_folds(X.shape[0], n_folds, seed, repeats=repeats)
    scores = np.empty((len(folds), lam.size))
    for k, ho in enumerate(folds):
        tr = np.setdiff1d(np.arange(X.shape[0]), ho, assume_unique=True)
        scaler = _scaler(X[tr])
        path = ridge_path(scaler.transform(X[tr]), y[tr], lam)
        scores[k] = score_rows("r2", y[ho], path.predict(scaler.transform(X[ho])))
    cv = scores.mean(axis=0)
    best = float(lam[int(np.argmax(cv))])
    scaler = _scaler(X)
    return StandardisedRidgeProbe(
        best, lam, cv, scores, scaler, ridge_path(scaler.transform(X), y, lam)
    )


@dataclass(frozen=True)
class FixedStandardisedRidge:
    """StandardScaler + ridge at a fixed lambda: the ``standardised`` probe inside controls."""

    lam: float

    def fit_predict(self, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray):
        """Scaler and ridge fitted on (X_train, y_train); predictions for X_test, (m,) or
        (m, B) for B target columns."""
        scaler = _scaler(X_train)
        coef, intercept, _ = ridge_fixed(scaler.transform(X_train), y_train, self.lam)
        return scaler.transform(np.asarray(X_test, dtype=np.float64)) @ coef + intercept

    def batches(self, refits: Refits) -> bool:
        """B target vectors on one unpermuted design: one scaler and factorisation for all."""
        one = len(refits.train) == 1 and refits.train[0].perm is None
        return one and refits.shared_design and np.ndim(refits.y) == 2

    def refit_many(self, refits: Refits, *, batched: bool | None = None) -> Refitted:
        """(B, m) test predictions of B refits at this lambda (see `batches`)."""
        if batched is not False and self.batches(refits):
            preds = self.fit_predict(
                refits.train[0].data, refits.y.T.astype(np.float64), refits.test[0].data
            )
            return Refitted(np.asarray(preds).T, {"multi_target": refits.n_problems})
        return Refitted(refits.loop(self.fit_predict), {"refits": refits.n_problems})
