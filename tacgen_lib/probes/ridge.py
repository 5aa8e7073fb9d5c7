"""Ridge probes on frozen features (mass, force): the regulariser path, CV, the refit.

The ridge numerics of the paper's property-prediction tables, in three modules: `ridge_path`
(the path and the guarded eigendecomposition), `ridge_cv` (λ by CV) and this one (the probe):

- `ridge_path.ridge_path`: ridge regression for a whole grid of regularisers from ONE singular value
  decomposition of the centred design matrix. The intercept is unpenalised, exactly as
  scikit-learn's ``Ridge(alpha=lam, fit_intercept=True)``: coefficients are
  ``V diag(s / (s^2 + lam)) U^T (y - mean(y))`` and the intercept is
  ``mean(y) - mean(X) @ coef``.
- `ridge_cv.select_lambda_cv`: the regulariser chosen by K-fold cross-validation on the TRAINING rows
  only (mean held-out R^2 over folds, first best in grid order on ties -- the rule of
  ``GridSearchCV(Ridge)``), one decomposition per fold reused for every lambda.
- `fit_ridge_probe` / `FixedRidge`: the probe refit at the selected lambda.
- `FixedRidge.refit_many`: the B refits of a control (`refits.Refits`) at the chosen lambda.

Numerical notes. Cross-validation works on eigendecompositions of centred Gram matrices
(the squared singular values), several times cheaper than SVDs: with more features than
rows, ONE decomposition of the training Gram gives every fold's held-out predictions through
the block-deletion identity; otherwise each fold's p x p scatter matrix is decomposed once.
Squaring loses singular directions below ``sqrt(eps)`` of the largest one; that is harmless
whenever the smallest lambda exceeds ``GRAM_GUARD`` times the eigenvalue error scale, and
otherwise the folds fall back to the SVD. `ridge_path` itself always uses the SVD.
BLAS threads: on a shared machine, cap them at the rule's ``threads`` (OPENBLAS_NUM_THREADS /
threadpoolctl); oversubscribed BLAS threads slow these solves by an order of magnitude.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from tacgen_lib.probes.batched import concat_ridge_permuted
from tacgen_lib.probes.input_checks import check_features, check_target
from tacgen_lib.probes.refits import Refits, Refitted
from tacgen_lib.probes.ridge_cv import LambdaSelection, select_lambda_cv
from tacgen_lib.probes.ridge_path import (
    GRAM_GUARD,
    guarded_eigh,
    ridge_fixed,
    ridge_path,
)


@dataclass(frozen=True)
class FixedRidge:
    """Ridge at a fixed lambda, the probe refit by controls and resampling diagnostics.

    solver: how `refit_many` solves B row permutations of the tactile block of a concat
    design in the kernel form (`batched.concat_ridge_permuted`): batched "pcg", with a
    Cholesky factorisation for permutations it does not converge on, or "cholesky" for all.
    """

    lam: float
    solver: Literal["pcg", "cholesky"] = "pcg"

    def fit_predict(self, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray):
        """Fit on (X_train, y_train), return predictions for X_test: (m,) or (m, B)."""
        coef, intercept, _ = ridge_fixed(X_train, y_train, self.lam)
        return np.asarray(X_test, dtype=np.float64) @ coef + intercept

    def _many_targets(self, refits: Refits) -> bool:
        """B target vectors on one design: one factorisation serves them all."""
        one = len(refits.train) == 1 and refits.train[0].perm is None
        return one and refits.shared_design and np.ndim(refits.y) == 2

    def _permuted_tactile(self, refits: Refits) -> bool:
        """[V, P_j T] for B permutations, solvable in the kernel form (`kernel_path_ok`)."""
        if len(refits.train) != 2 or refits.fusion != "concat" or not refits.shared_design:
            return False
        v, t = refits.train
        return (
            v.perm is None
            and t.perm is not None
            and np.ndim(refits.y) == 1
            and kernel_path_ok(v.data, t.data, self.lam)
        )

    def batches(self, refits: Refits) -> bool:
        """Whether `refit_many` solves these refits together."""
        return self._many_targets(refits) or self._permuted_tactile(refits)

    def refit_many(self, refits: Refits, *, batched: bool | None = None) -> Refitted:
        """(B, m) test predictions of B refits: permuted targets of one design through one
        factorisation (multi-target ridge), a permuted tactile block of a concat design by
        `concat_ridge_permuted`, anything else one refit at a time. ``batched=False`` forces
        the one-at-a-time path; ridge has no other batched solver to force."""
        if batched is not False and self._many_targets(refits):
            x_train, x_test = refits.train[0].data, refits.test[0].data
            coef, icpt, _ = ridge_fixed(x_train, refits.y.T.astype(np.float64), self.lam)
            preds = (np.asarray(x_test, np.float64) @ coef + icpt).T  # (B, m)
            return Refitted(preds, {"multi_target": refits.n_problems})
        if batched is not False and self._permuted_tactile(refits):
            (v, t), (v_te, t_te) = refits.train, refits.test
            preds, info = concat_ridge_permuted(
                v.data,
                t.data,
                refits.y.astype(np.float64),
                v_te.data,
                t_te.data,
                self.lam,
                t.perm,
                t_te.perm,
                solver=self.solver,
            )
            return Refitted(preds, info)
        return Refitted(refits.loop(self.fit_predict), {"refits": refits.n_problems})


def kernel_path_ok(v_tr: np.ndarray, t_tr: np.ndarray, lam: float) -> bool:
    """Dual path is worth it (p >= n) and accurate (lambda resolvable in the squared system)."""
    n, p = v_tr.shape[0], v_tr.shape[1] + t_tr.shape[1]
    bound = np.sum((v_tr - v_tr.mean(0)) ** 2) + np.sum((t_tr - t_tr.mean(0)) ** 2)  # >= e_max
    return p >= n and max(n, p) * np.finfo(np.float64).eps * bound * GRAM_GUARD <= lam


@dataclass(frozen=True)
class RidgeProbe:
    """A ridge probe: CV-selected lambda and the refit on all training rows.

    ``grid_coefs`` / ``grid_intercepts`` hold the refit at EVERY lambda of the CV grid (same
    decomposition), for the lambda sweep; ``coef`` / ``intercept`` are the selected row.
    """

    selection: LambdaSelection
    coef: np.ndarray
    intercept: float
    grid_coefs: np.ndarray | None = field(default=None, repr=False)  # (L, p)
    grid_intercepts: np.ndarray | None = field(default=None, repr=False)  # (L,)

    @property
    def lam(self) -> float:
        return self.selection.lam

    def predict(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        X = check_features(X, name="X_test", sample_ids=sample_ids)
        if X.shape[1] != self.coef.shape[0]:
            raise ValueError(f"X_test: {X.shape[1]} features, probe has {self.coef.shape[0]}")
        return X @ self.coef + self.intercept

    def predict_grid(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        """Predictions of the refit at every lambda of the grid: (L, m), grid order."""
        X = check_features(X, name="X_test", sample_ids=sample_ids)
        if self.grid_coefs is None or X.shape[1] != self.grid_coefs.shape[1]:
            raise ValueError(f"X_test: {X.shape[1]} features, probe has {self.coef.shape[0]}")
        return self.grid_coefs @ X.T + self.grid_intercepts[:, None]


def _grid_refit(
    X: np.ndarray,
    y: np.ndarray,
    lam: np.ndarray,
    eig: tuple[str, np.ndarray, np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Ridge on all rows at every lambda: (coefs (L, p), intercepts (L,)), one decomposition.

    Reuses the CV's eigenpairs when given -- of the centred Gram (dual:
    ``coef = X0^T U diag(1/(e + lam)) U^T y_c``) or of the scatter (primal:
    ``coef = W diag(1/(e + lam)) W^T X0^T y_c``); else, with p <= n, decomposes the scatter
    when the smallest lambda passes the `GRAM_GUARD` test; otherwise `ridge_path`'s SVD.
    """
    x_mean = X.mean(axis=0)
    y_mean = float(y.mean())
    x0, yc = X - x_mean, y - y_mean
    n, p = X.shape
    coefs = None
    if eig is not None and eig[0] == "dual":
        e, u = eig[1:]
        coefs = ((u.T @ yc) / (e + lam[:, None])) @ u.T @ x0
    elif eig is not None:
        e, w = eig[1:]
        coefs = ((w.T @ (x0.T @ yc)) / (e + lam[:, None])) @ w.T
    elif p <= n and (scatter := guarded_eigh(x0.T @ x0, max(n, p), lam.min())) is not None:
        e, w, good = scatter
        e, w = e[good], w[:, good]
        coefs = ((w.T @ (x0.T @ yc)) / (e + lam[:, None])) @ w.T
    if coefs is None:
        path = ridge_path(X, y, lam)
        return path.coefs, path.intercepts
    return coefs, y_mean - coefs @ x_mean


def fit_ridge_probe(
    X_train: np.ndarray,
    y_train: np.ndarray,
    lambdas: Sequence[float] | np.ndarray,
    *,
    n_folds: int,
    seed: int,
    repeats: int,
    sample_ids: Sequence | np.ndarray | None = None,
) -> RidgeProbe:
    """Select lambda by CV on the training rows, then refit on all of them (mass, force).

    The refit is computed for the whole grid from one decomposition (the CV's own Gram
    eigenpairs when its deletion path ran), equal to ``Ridge(alpha=lam)`` for each lambda.
    """
    sel = select_lambda_cv(
        X_train,
        y_train,
        lambdas,
        n_folds=n_folds,
        seed=seed,
        sample_ids=sample_ids,
        repeats=repeats,
    )
    X = check_features(X_train, sample_ids=sample_ids)
    y = check_target(y_train, X.shape[0], sample_ids=sample_ids)
    coefs, intercepts = _grid_refit(X, y, sel.lambdas, sel._eig)
    best = int(np.flatnonzero(sel.lambdas == sel.lam)[0])
    return RidgeProbe(sel, coefs[best], float(intercepts[best]), coefs, intercepts)
