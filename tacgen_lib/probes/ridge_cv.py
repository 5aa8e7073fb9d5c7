"""The ridge regulariser chosen by K-fold cross-validation on the TRAINING rows only (mean
held-out R^2 over folds, first best in grid order on ties -- the rule of
``GridSearchCV(Ridge)``): one decomposition per fold reused for every lambda, or, with more
features than rows, ONE decomposition of the training Gram and the block-deletion identity
for every fold's held-out predictions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from tacgen_lib.probes.blas_threads import single_blas_thread
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.input_checks import check_features, check_lambdas, check_target
from tacgen_lib.probes.ridge_path import (
    FLOAT64_EPS,
    GRAM_GUARD,
    guarded_eigh,
    ridge_path,
)


@dataclass(frozen=True)
class LambdaCV:
    """A lambda chosen by K-fold CV: the chosen `lam`, the grid, the mean held-out R^2 per
    lambda and each fold's (every ridge probe's selection: `LambdaSelection`, the standardised
    probe of `tacgen_lib.probes.scaling`)."""

    lam: float
    lambdas: np.ndarray  # (L,)
    cv_scores: np.ndarray  # (L,) mean held-out R^2
    fold_scores: np.ndarray  # (K, L)

    @property
    def best(self) -> int:
        """The chosen lambda's position in the grid."""
        return int(np.flatnonzero(self.lambdas == self.lam)[0])


@dataclass(frozen=True)
class LambdaSelection(LambdaCV):
    """Outcome of `select_lambda_cv`: the `LambdaCV` with its folds and solvers."""

    folds: list[np.ndarray]
    solver: list[str]  # per fold: "deletion", "gram" or "svd"
    # when a deletion path ran: ("dual", e, U) eigenpairs of the centred training Gram, or
    # ("primal", e, W) of the centred scatter; reused by the refit
    _eig: tuple[str, np.ndarray, np.ndarray] | None = field(default=None, repr=False)


def _r2_rows(y: np.ndarray, preds: np.ndarray) -> np.ndarray:
    """R^2 of each row of preds (L, m) against y (m,), with the `r2` constant-target rule."""
    ss_res = np.sum((preds - y) ** 2, axis=1)
    if y.min() == y.max():
        return np.where(ss_res == 0.0, 1.0, 0.0)
    ss_tot = np.sum((y - y.mean()) ** 2)
    return 1.0 - ss_res / ss_tot


def _fold_predictions(
    X0: np.ndarray,
    G0: np.ndarray | None,
    y: np.ndarray,
    tr: np.ndarray,
    ho: np.ndarray,
    lam: np.ndarray,
) -> tuple[np.ndarray, str]:
    """Held-out predictions (L, |ho|) of ridge fitted on rows tr, for every lambda."""
    n_tr, p = tr.size, X0.shape[1]
    ytr = y[tr]
    ym = ytr.mean()
    yc = ytr - ym
    if p <= n_tr:  # primal: eigh of the p x p centred scatter matrix
        m = X0[tr].mean(axis=0)
        xc = X0[tr] - m
        e, w = np.linalg.eigh(xc.T @ xc)
        err = max(n_tr, p) * FLOAT64_EPS * max(e[-1], 0.0)
        if err * GRAM_GUARD <= lam.min():
            good = e > err
            e, w = e[good], w[:, good]
            a = (X0[ho] - m) @ w  # (m, k)
            b = w.T @ (xc.T @ yc)  # (k,)
            return ym + (b / (e + lam[:, None])) @ a.T, "gram"
    elif G0 is not None:  # dual: eigh of the n_tr x n_tr centred Gram, from the shared G0
        g = G0[np.ix_(tr, tr)]
        r = g.mean(axis=1)
        gm = r.mean()
        kc = g - r[:, None] - r[None, :] + gm
        e, u = np.linalg.eigh(kc)
        err = max(n_tr, p) * FLOAT64_EPS * max(e[-1], 0.0)
        if err * GRAM_GUARD <= lam.min():
            good = e > err
            e, u = e[good], u[:, good]
            kx = G0[np.ix_(ho, tr)]
            kx = kx - kx.mean(axis=1)[:, None] - r[None, :] + gm
            a = kx @ u  # (m, k)
            b = u.T @ yc
            return ym + (b / (e + lam[:, None])) @ a.T, "gram"
    path = ridge_path(X0[tr], ytr, lam)
    return path.predict(X0[ho]), "svd"


def _fold_deletions(
    block: Callable[[np.ndarray, int], np.ndarray],
    resid: np.ndarray,
    y: np.ndarray,
    folds: list[np.ndarray],
) -> list[np.ndarray] | None:
    """Held-out predictions ``y_f - [(I - H)_ff]^{-1} (I - H)_f y`` for every fold f and lambda i.

    block(f, i) is the fold's block of I - H at lambda i; resid (L, n) is (I - H) y. Returns
    None when a block is not positive definite (the caller then decomposes each fold).
    """
    out = []
    for ho in folds:
        preds = np.empty((resid.shape[0], ho.size))
        for i in range(resid.shape[0]):
            try:
                r = scipy.linalg.cho_solve(
                    scipy.linalg.cho_factor(block(ho, i), lower=True, check_finite=False),
                    resid[i, ho],
                    check_finite=False,
                )
            except np.linalg.LinAlgError:
                return None
            preds[i] = y[ho] - r
        out.append(preds)
    return out


def _deletion_predictions(
    G0: np.ndarray, y: np.ndarray, folds: list[np.ndarray], lam: np.ndarray
) -> tuple[list[np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
    """Held-out predictions of every fold and lambda from ONE eigendecomposition (dual form).

    Block-deletion identity of penalised least squares with a fixed quadratic penalty (here
    ridge with an unpenalised intercept): the residual of the fit without fold f equals
    ``[(I - H)_ff]^{-1} (I - H)_f y`` with H the full-data hat matrix,
    ``I - H = sum_i lam / (e_i + lam) u_i u_i^T + (projector on the null space of Kc,
    minus J / n)``, from the eigenpairs (e_i, u_i) of the centred Gram Kc = G0. The factors
    lam / (e_i + lam) are formed directly (no 1 - x cancellation). Returns None when lambda
    is too small for the Gram's eigenvalue error (the caller then decomposes each fold).
    Also returns the positive eigenpairs (e, U) of G0, from which the refit on all rows is
    ``coef = X0^T U diag(1 / (e + lam)) U^T y_c`` (`fit_ridge_probe` reuses them).
    """
    n = y.size
    eig = guarded_eigh(G0, n, lam.min())
    if eig is None:
        return None
    e, u, pos = eig
    up, ep, u0 = u[:, pos], e[pos], u[:, ~pos]
    yc = y - y.mean()
    g = lam[:, None] / (ep + lam[:, None])  # (L, k)
    resid = (g * (up.T @ yc)) @ up.T + u0 @ (u0.T @ yc)  # (L, n): (I - H) y for each lambda

    def block(ho: np.ndarray, i: int) -> np.ndarray:
        uf, u0f = up[ho], u0[ho]
        return (uf * g[i]) @ uf.T + u0f @ u0f.T - 1.0 / n

    out = _fold_deletions(block, resid, y, folds)
    return None if out is None else (out, (ep, up))


def _deletion_predictions_primal(
    X0: np.ndarray, y: np.ndarray, folds: list[np.ndarray], lam: np.ndarray
) -> tuple[list[np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
    """`_deletion_predictions` for p < n, from ONE eigendecomposition of the p x p scatter.

    With X0^T X0 = W diag(e) W^T and U = X0 W diag(e^-1/2) (n x k), the hat matrix is
    ``H = J / n + U diag(e / (e + lam)) U^T``, so each fold needs the small block
    ``(I - H)_ff = I - J / n - U_f diag(e / (e + lam)) U_f^T`` and the same block-deletion
    identity gives its held-out predictions. Returns None under the same `GRAM_GUARD` test
    or when a block is not positive definite (the caller then decomposes each fold); else
    also the primal eigenpairs (e, W) for the refit.
    """
    n, p = X0.shape
    eig = guarded_eigh(X0.T @ X0, max(n, p), lam.min())
    if eig is None:
        return None
    e, w, pos = eig
    e, w = e[pos], w[:, pos]
    u = (X0 @ w) / np.sqrt(e)
    yc = y - y.mean()
    h = e / (e + lam[:, None])  # (L, k)
    resid = yc - (h * (u.T @ yc)) @ u.T  # (L, n): (I - H) y for each lambda

    def block(ho: np.ndarray, i: int) -> np.ndarray:
        uf = u[ho]
        a = -((uf * h[i]) @ uf.T) - 1.0 / n
        a[np.diag_indices_from(a)] += 1.0
        return a

    out = _fold_deletions(block, resid, y, folds)
    return None if out is None else (out, (e, w))


def select_lambda_cv(
    X: np.ndarray,
    y: np.ndarray,
    lambdas: Sequence[float] | np.ndarray,
    *,
    n_folds: int,
    seed: int,
    repeats: int,
    folds: list[np.ndarray] | None = None,
    sample_ids: Sequence | np.ndarray | None = None,
) -> LambdaSelection:
    """Choose lambda by K-fold CV on the training rows (mean held-out R^2, first best in grid).

    Pass only TRAINING rows. Folds come from `make_folds(n, n_folds, seed, repeats=repeats)`
    unless given (repeated K-fold: the mean is over every fold of every draw).
    One eigendecomposition serves every fold and lambda through the block-deletion identity:
    of the centred Gram with more features than fold-training rows
    (`_deletion_predictions`), else of the p x p scatter (`_deletion_predictions_primal`);
    if lambda is too small for the squared system, each fold is decomposed (or SVD'd) once
    and serves every lambda. The selection equals
    ``GridSearchCV(Ridge(), {"alpha": lambdas}, cv=<same folds>)``.
    """
    X = check_features(X, sample_ids=sample_ids)
    y = check_target(y, X.shape[0], sample_ids=sample_ids)
    lam = check_lambdas(lambdas)
    n, p = X.shape
    if folds is None:
        folds = make_folds(n, n_folds, seed, repeats=repeats)
    X0 = X - X.mean(axis=0)  # shared centring keeps the Gram free of large-offset cancellation
    G0 = X0 @ X0.T if p > n - max(len(f) for f in folds) else None
    scores = np.empty((len(folds), lam.size))
    solver = []
    # one BLAS thread: the deletion paths' many small solves run slower with two, and their
    # eigh gains little
    with single_blas_thread():
        if G0 is not None:
            deleted, kind = _deletion_predictions(G0, y, folds, lam), "dual"
        else:
            deleted, kind = _deletion_predictions_primal(X0, y, folds, lam), "primal"
    eig = None if deleted is None else (kind, *deleted[1])
    for k, ho in enumerate(folds):
        if deleted is not None:
            preds, how = deleted[0][k], "deletion"
        else:
            tr = np.setdiff1d(np.arange(n), ho, assume_unique=True)
            preds, how = _fold_predictions(X0, G0, y, tr, ho, lam)
        scores[k] = _r2_rows(y[ho], preds)
        solver.append(how)
    cv = scores.mean(axis=0)
    best = int(np.argmax(cv))
    return LambdaSelection(float(lam[best]), lam, cv, scores, list(folds), solver, eig)
