"""Ridge probes on frozen features (mass, force): the regulariser path, CV, the refit.

This module owns the ridge numerics of the paper's property-prediction tables:

- `ridge_path`: ridge regression for a whole grid of regularisers from ONE singular value
  decomposition of the centred design matrix. The intercept is unpenalised, exactly as
  scikit-learn's ``Ridge(alpha=lam, fit_intercept=True)``: coefficients are
  ``V diag(s / (s^2 + lam)) U^T (y - mean(y))`` and the intercept is
  ``mean(y) - mean(X) @ coef``.
- `select_lambda_cv`: the regulariser chosen by K-fold cross-validation on the TRAINING rows
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
threadpoolctl); oversubscribed BLAS threads slow these solves by more than 10x.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.linalg

from tacgen_lib.probes.batched import concat_ridge_permuted
from tacgen_lib.probes.blas import single_blas_thread
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.inputs import check_features, check_lambdas, check_target
from tacgen_lib.probes.refits import Refits, Refitted

__all__ = [
    "GRAM_GUARD",
    "FixedRidge",
    "LambdaSelection",
    "RidgePath",
    "RidgeProbe",
    "fit_ridge_probe",
    "guarded_eigh",
    "kernel_path_ok",
    "ridge_fixed",
    "ridge_path",
    "select_lambda_cv",
]

_EPS = np.finfo(np.float64).eps

# Gram eigenvalues carry an absolute error of about max(n, p) * eps * e_max. The Gram path
# is used only if that error, divided by the smallest lambda, stays below 1 / GRAM_GUARD:
# predictions are then accurate to ~1e-6 relative, far below CV noise.
GRAM_GUARD = 1e6


# --------------------------------------------------------------------------- ridge path


@dataclass(frozen=True)
class RidgePath:
    """Ridge solutions for a grid of lambdas, from one SVD of the centred training matrix."""

    lambdas: np.ndarray  # (L,)
    coefs: np.ndarray  # (L, p)
    intercepts: np.ndarray  # (L,)
    x_mean: np.ndarray  # (p,)
    y_mean: float
    _vt: np.ndarray = field(repr=False)  # (k, p) right singular vectors
    _shrunk: np.ndarray = field(repr=False)  # (L, k) = s/(s^2+lam) * (U^T y_c)

    def predict(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        """Predictions of every lambda at once: (L, m) for X of shape (m, p)."""
        X = check_features(X, name="X_new", sample_ids=sample_ids)
        if X.shape[1] != self.x_mean.shape[0]:
            raise ValueError(
                f"X_new: {X.shape[1]} features, the path was fitted on {self.x_mean.shape[0]}"
            )
        a = (X - self.x_mean) @ self._vt.T  # (m, k)
        return self.y_mean + self._shrunk @ a.T


def ridge_path(
    X: np.ndarray,
    y: np.ndarray,
    lambdas: Sequence[float] | np.ndarray,
    *,
    sample_ids: Sequence | np.ndarray | None = None,
) -> RidgePath:
    """Ridge regression for every lambda in the grid from one SVD of the centred X.

    Equal to ``sklearn.linear_model.Ridge(alpha=lam, fit_intercept=True)`` for each lambda
    (unpenalised intercept). Singular values below ``max(n, p) * eps * s_max`` are treated as
    zero (numerical rank, as ``numpy.linalg.lstsq``); for lambda > 0 they contribute at most
    ``s / lambda`` to a coefficient and nothing measurable to a prediction.
    """
    X = check_features(X, sample_ids=sample_ids)
    y = check_target(y, X.shape[0], sample_ids=sample_ids)
    lam = check_lambdas(lambdas)
    x_mean = X.mean(axis=0)
    y_mean = float(y.mean())
    u, s, vt = scipy.linalg.svd(X - x_mean, full_matrices=False, lapack_driver="gesdd")
    keep = s > (max(X.shape) * _EPS * (s[0] if s.size else 0.0))
    u, s, vt = u[:, keep], s[keep], vt[keep]
    uty = u.T @ (y - y_mean)
    shrunk = (s / (s**2 + lam[:, None])) * uty  # (L, k)
    coefs = shrunk @ vt
    intercepts = y_mean - coefs @ x_mean
    return RidgePath(lam, coefs, intercepts, x_mean, y_mean, vt, shrunk)


def ridge_fixed(
    X: np.ndarray, Y: np.ndarray, lam: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ridge at one lambda for one or many targets: (coef (p, B), intercept (B,), x_mean).

    Y is (n,) or (n, B) -- B targets share one Cholesky factorisation (the label-permutation
    control passes all its permuted targets at once). Solved in the primal (p x p) or dual
    (n x n) form, whichever is smaller; falls back to the SVD path if lambda is too small for
    the squared system to be factorised accurately.
    """
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    one = Y.ndim == 1
    Y2 = Y[:, None] if one else Y
    x_mean = X.mean(axis=0)
    y_mean = Y2.mean(axis=0)
    xc = X - x_mean
    yc = Y2 - y_mean
    n, p = xc.shape
    gram = xc.T @ xc if p <= n else xc @ xc.T
    e_max = float(np.linalg.norm(gram))  # Frobenius norm >= largest eigenvalue; O(size)
    if max(n, p) * _EPS * e_max * GRAM_GUARD <= lam:
        gram[np.diag_indices_from(gram)] += lam
        try:
            factor = scipy.linalg.cho_factor(gram, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            factor = None
        if factor is not None:
            if p <= n:
                coef = scipy.linalg.cho_solve(factor, xc.T @ yc, check_finite=False)
            else:
                coef = xc.T @ scipy.linalg.cho_solve(factor, yc, check_finite=False)
            intercept = y_mean - x_mean @ coef
            return (coef[:, 0], intercept[0], x_mean) if one else (coef, intercept, x_mean)
    u, s, vt = scipy.linalg.svd(xc, full_matrices=False, lapack_driver="gesdd")
    keep = s > (max(n, p) * _EPS * (s[0] if s.size else 0.0))
    u, s, vt = u[:, keep], s[keep], vt[keep]
    coef = vt.T @ ((s / (s**2 + lam))[:, None] * (u.T @ yc))
    intercept = y_mean - x_mean @ coef
    return (coef[:, 0], intercept[0], x_mean) if one else (coef, intercept, x_mean)


# --------------------------------------------------------------------------- CV


@dataclass(frozen=True)
class LambdaSelection:
    """Outcome of `select_lambda_cv`."""

    lam: float
    lambdas: np.ndarray  # (L,)
    cv_scores: np.ndarray  # (L,) mean held-out R^2
    fold_scores: np.ndarray  # (K, L)
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
        err = max(n_tr, p) * _EPS * max(e[-1], 0.0)
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
        err = max(n_tr, p) * _EPS * max(e[-1], 0.0)
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


def guarded_eigh(
    m: np.ndarray, size: int, lam_min: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Eigenpairs (e, v) of the symmetric PSD `m` and the mask of eigenvalues above their error,
    or None when that error (``size * eps * e_max``) is too large for `lam_min` (`GRAM_GUARD`).
    """
    e, v = scipy.linalg.eigh(m, driver="evd", check_finite=False)  # evd: ~1.3x numpy's
    err = size * _EPS * max(e[-1], 0.0)
    if err * GRAM_GUARD > lam_min:
        return None
    return e, v, e > err


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
    n_folds: int = 5,
    seed: int = 0,
    folds: list[np.ndarray] | None = None,
    sample_ids: Sequence | np.ndarray | None = None,
) -> LambdaSelection:
    """Choose lambda by K-fold CV on the training rows (mean held-out R^2, first best in grid).

    Pass only TRAINING rows. Folds come from `make_folds(n, n_folds, seed)` unless given.
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
        folds = make_folds(n, n_folds, seed)
    X0 = X - X.mean(axis=0)  # shared centring keeps the Gram free of large-offset cancellation
    G0 = X0 @ X0.T if p > n - max(len(f) for f in folds) else None
    scores = np.empty((len(folds), lam.size))
    solver = []
    # one BLAS thread: the deletion paths' many small solves ran 2-5x slower with two
    # (measured), and their eigh gains ~10%
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


# --------------------------------------------------------------------------- refits


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
    n_folds: int = 5,
    seed: int = 0,
    sample_ids: Sequence | np.ndarray | None = None,
) -> RidgeProbe:
    """Select lambda by CV on the training rows, then refit on all of them (mass, force).

    The refit is computed for the whole grid from one decomposition (the CV's own Gram
    eigenpairs when its deletion path ran), equal to ``Ridge(alpha=lam)`` for each lambda.
    """
    sel = select_lambda_cv(
        X_train, y_train, lambdas, n_folds=n_folds, seed=seed, sample_ids=sample_ids
    )
    X = check_features(X_train, sample_ids=sample_ids)
    y = check_target(y_train, X.shape[0], sample_ids=sample_ids)
    coefs, intercepts = _grid_refit(X, y, sel.lambdas, sel._eig)
    best = int(np.flatnonzero(sel.lambdas == sel.lam)[0])
    return RidgeProbe(sel, coefs[best], float(intercepts[best]), coefs, intercepts)
