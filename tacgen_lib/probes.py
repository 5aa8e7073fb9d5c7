"""Linear probes on frozen features: ridge (mass, force) and logistic (density, hardness).

This module owns the probe numerics of the paper's property-prediction tables:

- `ridge_path`: ridge regression for a whole grid of regularisers from ONE singular value
  decomposition of the centred design matrix. The intercept is unpenalised, exactly as
  scikit-learn's ``Ridge(alpha=lam, fit_intercept=True)``: coefficients are
  ``V diag(s / (s^2 + lam)) U^T (y - mean(y))`` and the intercept is
  ``mean(y) - mean(X) @ coef``.
- `select_lambda_cv`: the regulariser chosen by K-fold cross-validation on the TRAINING rows
  only (mean held-out R^2 over folds, first best in grid order on ties -- the rule of
  ``GridSearchCV(Ridge)``), one decomposition per fold reused for every lambda.
- `fit_ridge_probe` / `FixedRidge`: the probe refit at the selected lambda.
- `fit_logistic` / `FixedLogistic`: scikit-learn ``LogisticRegression`` (lbfgs; multinomial
  for more than two classes) on standardised features, C chosen by stratified K-fold CV on
  the training rows. Convergence is never silently assumed: a ``ConvergenceWarning`` doubles
  ``max_iter`` and refits, up to a cap; iterations and convergence are recorded, and a probe
  that still fails to converge re-emits the warning.
- `r2`, `accuracy`: the probe metrics, equal to ``sklearn.metrics.r2_score`` /
  ``accuracy_score``.
- `check_features`, `check_target`: input validation; a non-finite feature is reported with
  the offending ``sample_id``.

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

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

__all__ = [
    "FixedLogistic",
    "FixedRidge",
    "LambdaSelection",
    "LogisticProbe",
    "RidgePath",
    "RidgeProbe",
    "accuracy",
    "check_features",
    "check_target",
    "fit_logistic",
    "fit_ridge_probe",
    "make_folds",
    "r2",
    "ridge_fixed",
    "ridge_path",
    "select_lambda_cv",
]

_EPS = np.finfo(np.float64).eps
# Gram eigenvalues carry an absolute error of about max(n, p) * eps * e_max. The Gram path
# is used only if that error, divided by the smallest lambda, stays below 1 / GRAM_GUARD:
# predictions are then accurate to ~1e-6 relative, far below CV noise.
GRAM_GUARD = 1e6


# --------------------------------------------------------------------------- validation


def _row_name(i: int, sample_ids: Sequence | np.ndarray | None) -> str:
    if sample_ids is None:
        return f"row {i}"
    return f"sample_id {str(sample_ids[i])!r}"


def check_features(
    X: np.ndarray, *, name: str = "X", sample_ids: Sequence | np.ndarray | None = None
) -> np.ndarray:
    """Return X as a finite float64 (n, p) array, or raise ValueError naming the bad sample.

    sample_ids, if given, must have one id per row; it is used only in error messages.
    """
    arr = np.asarray(X)
    if arr.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D (samples, features) array, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{name}: expected numeric features, got dtype {arr.dtype}")
    if sample_ids is not None and len(sample_ids) != arr.shape[0]:
        raise ValueError(
            f"{name}: {arr.shape[0]} rows but {len(sample_ids)} sample_ids; pass one id per row"
        )
    arr = np.asarray(arr, dtype=np.float64)
    finite = np.isfinite(arr)
    if not finite.all():
        i, j = np.argwhere(~finite)[0]
        raise ValueError(
            f"{name}: {_row_name(int(i), sample_ids)} has non-finite value {arr[i, j]!r} in "
            f"feature column {int(j)}; fix or drop that sample upstream before probing"
        )
    return arr


def check_target(
    y: np.ndarray,
    n: int,
    *,
    name: str = "y",
    sample_ids: Sequence | np.ndarray | None = None,
    numeric: bool = True,
) -> np.ndarray:
    """Return y as a 1-D array of length n (float64 and finite when numeric)."""
    arr = np.asarray(y)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D target, got shape {arr.shape}")
    if arr.shape[0] != n:
        raise ValueError(f"{name}: {arr.shape[0]} targets for {n} feature rows; they must match")
    if not numeric:
        return arr
    arr = np.asarray(arr, dtype=np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name}: {_row_name(i, sample_ids)} has non-finite target {arr[i]!r}; "
            "drop or relabel that sample"
        )
    return arr


def _check_lambdas(lambdas: Sequence[float] | np.ndarray) -> np.ndarray:
    lam = np.atleast_1d(np.asarray(lambdas, dtype=np.float64))
    if lam.ndim != 1 or lam.size == 0:
        raise ValueError(f"lambdas: expected a non-empty 1-D grid, got shape {lam.shape}")
    if not (np.isfinite(lam).all() and (lam > 0).all()):
        raise ValueError(f"lambdas: every regulariser must be finite and > 0, got {lam.tolist()}")
    return lam


# --------------------------------------------------------------------------- metrics


def r2(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """Coefficient of determination, equal to ``sklearn.metrics.r2_score``.

    A constant target (SS_tot = 0) follows scikit-learn's ``force_finite`` rule: 1.0 when the
    predictions are perfect, else 0.0. Constancy is tested exactly (min == max), so a constant
    target whose mean rounds is still recognised.
    """
    y = np.asarray(y_true, dtype=np.float64)
    p = np.asarray(y_pred, dtype=np.float64)
    if y.shape != p.shape or y.ndim != 1:
        raise ValueError(f"r2: y_true {y.shape} and y_pred {p.shape} must be equal 1-D shapes")
    ss_res = float(np.sum((y - p) ** 2))
    if y.min() == y.max():
        return 1.0 if ss_res == 0.0 else 0.0
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return 1.0 - ss_res / ss_tot


def accuracy(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """Fraction of correct labels, equal to ``sklearn.metrics.accuracy_score``."""
    y = np.asarray(y_true)
    p = np.asarray(y_pred)
    if y.shape != p.shape or y.ndim != 1:
        raise ValueError(f"accuracy: y_true {y.shape} and y_pred {p.shape} must be equal 1-D")
    return float(np.mean(y == p))


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
    lam = _check_lambdas(lambdas)
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


# --------------------------------------------------------------------------- folds + CV


def make_folds(
    n: int, n_folds: int, seed: int, *, labels: np.ndarray | None = None
) -> list[np.ndarray]:
    """Deterministic K-fold split of range(n): a list of sorted held-out index arrays.

    Rows are shuffled by ``numpy.random.default_rng(seed)``. With labels, each class is
    dealt round-robin over the folds (stratified), so every fold sees every class it can.
    """
    if not 2 <= n_folds <= n:
        raise ValueError(f"make_folds: need 2 <= n_folds <= n, got n_folds={n_folds}, n={n}")
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)
    if labels is None:
        return [np.sort(f) for f in np.array_split(order, n_folds)]
    labels = np.asarray(labels)
    assign = np.empty(n, dtype=np.int64)
    offset = 0
    for c in np.unique(labels):
        members = order[labels[order] == c]
        assign[members] = (offset + np.arange(members.size)) % n_folds
        offset += members.size
    return [np.flatnonzero(assign == k) for k in range(n_folds)]


@dataclass(frozen=True)
class LambdaSelection:
    """Outcome of `select_lambda_cv`."""

    lam: float
    lambdas: np.ndarray  # (L,)
    cv_scores: np.ndarray  # (L,) mean held-out R^2
    fold_scores: np.ndarray  # (K, L)
    folds: list[np.ndarray]
    solver: list[str]  # per fold: "deletion", "gram" or "svd"


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


def _deletion_predictions(
    G0: np.ndarray, y: np.ndarray, folds: list[np.ndarray], lam: np.ndarray
) -> list[np.ndarray] | None:
    """Held-out predictions of every fold and lambda from ONE eigendecomposition (dual form).

    Block-deletion identity of penalised least squares with a fixed quadratic penalty (here
    ridge with an unpenalised intercept): the residual of the fit without fold f equals
    ``[(I - H)_ff]^{-1} (I - H)_f y`` with H the full-data hat matrix,
    ``I - H = sum_i lam / (e_i + lam) u_i u_i^T + (projector on the null space of Kc,
    minus J / n)``, from the eigenpairs (e_i, u_i) of the centred Gram Kc = G0. The factors
    lam / (e_i + lam) are formed directly (no 1 - x cancellation). Returns None when lambda
    is too small for the Gram's eigenvalue error (the caller then decomposes each fold).
    """
    n = y.size
    e, u = np.linalg.eigh(G0)
    err = n * _EPS * max(e[-1], 0.0)
    if err * GRAM_GUARD > lam.min():
        return None
    pos = e > err
    up, ep, u0 = u[:, pos], e[pos], u[:, ~pos]
    yc = y - y.mean()
    g = lam[:, None] / (ep + lam[:, None])  # (L, k)
    resid = (g * (up.T @ yc)) @ up.T + u0 @ (u0.T @ yc)  # (L, n): (I - H) y for each lambda
    out = []
    for ho in folds:
        uf, u0f = up[ho], u0[ho]
        null_ff = u0f @ u0f.T - 1.0 / n
        preds = np.empty((lam.size, ho.size))
        for i in range(lam.size):
            a = (uf * g[i]) @ uf.T + null_ff
            try:
                r = scipy.linalg.cho_solve(
                    scipy.linalg.cho_factor(a, lower=True, check_finite=False),
                    resid[i, ho],
                    check_finite=False,
                )
            except np.linalg.LinAlgError:
                return None  # fold-train problem not positive definite: decompose per fold
            preds[i] = y[ho] - r
        out.append(preds)
    return out


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
    With more features than fold-training rows, one eigendecomposition of the centred Gram
    serves every fold and lambda (`_deletion_predictions`); otherwise each fold is
    decomposed once and serves every lambda. The selection equals
    ``GridSearchCV(Ridge(), {"alpha": lambdas}, cv=<same folds>)``.
    """
    X = check_features(X, sample_ids=sample_ids)
    y = check_target(y, X.shape[0], sample_ids=sample_ids)
    lam = _check_lambdas(lambdas)
    n, p = X.shape
    if folds is None:
        folds = make_folds(n, n_folds, seed)
    X0 = X - X.mean(axis=0)  # shared centring keeps the Gram free of large-offset cancellation
    G0 = X0 @ X0.T if p > n - max(len(f) for f in folds) else None
    scores = np.empty((len(folds), lam.size))
    solver = []
    deleted = _deletion_predictions(G0, y, folds, lam) if G0 is not None else None
    for k, ho in enumerate(folds):
        if deleted is not None:
            preds, how = deleted[k], "deletion"
        else:
            tr = np.setdiff1d(np.arange(n), ho, assume_unique=True)
            preds, how = _fold_predictions(X0, G0, y, tr, ho, lam)
        scores[k] = _r2_rows(y[ho], preds)
        solver.append(how)
    cv = scores.mean(axis=0)
    best = int(np.argmax(cv))
    return LambdaSelection(float(lam[best]), lam, cv, scores, list(folds), solver)


@dataclass(frozen=True)
class FixedRidge:
    """Ridge at a fixed lambda, the probe refit by controls and resampling diagnostics."""

    lam: float

    def fit_predict(self, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray):
        """Fit on (X_train, y_train), return predictions for X_test: (m,) or (m, B)."""
        coef, intercept, _ = ridge_fixed(X_train, y_train, self.lam)
        return np.asarray(X_test, dtype=np.float64) @ coef + intercept


@dataclass(frozen=True)
class RidgeProbe:
    """A ridge probe: CV-selected lambda and the refit on all training rows."""

    selection: LambdaSelection
    coef: np.ndarray
    intercept: float

    @property
    def lam(self) -> float:
        return self.selection.lam

    def predict(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        X = check_features(X, name="X_test", sample_ids=sample_ids)
        if X.shape[1] != self.coef.shape[0]:
            raise ValueError(f"X_test: {X.shape[1]} features, probe has {self.coef.shape[0]}")
        return X @ self.coef + self.intercept


def fit_ridge_probe(
    X_train: np.ndarray,
    y_train: np.ndarray,
    lambdas: Sequence[float] | np.ndarray,
    *,
    n_folds: int = 5,
    seed: int = 0,
    sample_ids: Sequence | np.ndarray | None = None,
) -> RidgeProbe:
    """Select lambda by CV on the training rows, then refit on all of them (mass, force)."""
    sel = select_lambda_cv(
        X_train, y_train, lambdas, n_folds=n_folds, seed=seed, sample_ids=sample_ids
    )
    coef, intercept, _ = ridge_fixed(X_train, y_train, sel.lam)
    return RidgeProbe(sel, coef, float(intercept))


# --------------------------------------------------------------------------- logistic


@dataclass(frozen=True)
class LogisticFit:
    """One converged (or honestly unconverged) standardised logistic regression."""

    model: Pipeline
    n_iter: int
    max_iter: int
    converged: bool


def _fit_logistic_once(
    X: np.ndarray, y: np.ndarray, C: float, max_iter: int, max_iter_cap: int, tol: float
) -> LogisticFit:
    """Standardise + lbfgs LogisticRegression; double max_iter on ConvergenceWarning.

    Warnings other than ConvergenceWarning are re-emitted; a fit that still fails at the
    cap re-emits a ConvergenceWarning and is recorded as converged=False.
    """
    it = max_iter
    while True:
        model = Pipeline(
            [
                ("standardise", StandardScaler()),
                ("logistic", LogisticRegression(C=C, solver="lbfgs", max_iter=it, tol=tol)),
            ]
        )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model.fit(X, y)
        conv = [w for w in caught if issubclass(w.category, ConvergenceWarning)]
        for w in caught:
            if not issubclass(w.category, ConvergenceWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        n_iter = int(np.max(model.named_steps["logistic"].n_iter_))
        if not conv:
            return LogisticFit(model, n_iter, it, True)
        if it >= max_iter_cap:
            warnings.warn(
                f"fit_logistic: lbfgs did not converge within max_iter={it} (C={C}); "
                "the probe is recorded as converged=False -- check feature scaling or C",
                ConvergenceWarning,
                stacklevel=3,
            )
            return LogisticFit(model, n_iter, it, False)
        it = min(2 * it, max_iter_cap)


@dataclass(frozen=True)
class LogisticProbe:
    """A logistic probe: CV-selected C, refit diagnostics, and the fitted pipeline."""

    C: float
    C_grid: np.ndarray
    cv_scores: np.ndarray  # (len(C_grid),) mean held-out accuracy
    fit: LogisticFit
    cv_converged: bool  # every fold fit converged
    cv_max_n_iter: int

    @property
    def n_iter(self) -> int:
        return self.fit.n_iter

    @property
    def converged(self) -> bool:
        return self.fit.converged

    def predict(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        return self.fit.model.predict(check_features(X, name="X_test", sample_ids=sample_ids))

    def predict_proba(self, X: np.ndarray, *, sample_ids: Sequence | np.ndarray | None = None):
        X = check_features(X, name="X_test", sample_ids=sample_ids)
        return self.fit.model.predict_proba(X)


def fit_logistic(
    X: np.ndarray,
    y: np.ndarray,
    C_grid: Sequence[float],
    seed: int,
    *,
    n_folds: int = 5,
    max_iter: int = 200,
    max_iter_cap: int = 12800,
    tol: float = 1e-6,
    sample_ids: Sequence | np.ndarray | None = None,
) -> LogisticProbe:
    """Logistic probe (density, hardness): C by stratified K-fold CV on the training rows.

    Features are standardised inside every fit (scaler fitted on that fit's training rows
    only), which keeps lbfgs well conditioned; with the L2 penalty the objective is strictly
    convex with a finite minimiser even for linearly separable classes, so lbfgs converges.
    Ties in CV accuracy go to the first C of the grid in the order given. ``tol`` is tighter
    than scikit-learn's 1e-4 default so the fitted probabilities agree with a float64
    reference optimum to ~1e-5.
    """
    X = check_features(X, sample_ids=sample_ids)
    y = check_target(y, X.shape[0], sample_ids=sample_ids, numeric=False)
    C = np.asarray(C_grid, dtype=np.float64)
    if C.ndim != 1 or C.size == 0 or not (np.isfinite(C).all() and (C > 0).all()):
        raise ValueError(f"fit_logistic: C_grid must be a non-empty list of C > 0, got {C_grid}")
    classes, counts = np.unique(y, return_counts=True)
    if classes.size < 2:
        raise ValueError("fit_logistic: training rows hold a single class; nothing to probe")
    k = int(min(n_folds, counts.min()))
    if k < 2:
        raise ValueError(
            f"fit_logistic: class {classes[np.argmin(counts)]!r} has {counts.min()} training "
            "row(s); stratified CV needs at least 2 per class"
        )
    folds = make_folds(X.shape[0], k, seed, labels=y)
    scores = np.zeros((k, C.size))
    all_conv = True
    worst = 0
    for f, ho in enumerate(folds):
        tr = np.setdiff1d(np.arange(X.shape[0]), ho, assume_unique=True)
        for c, cval in enumerate(C):
            fit = _fit_logistic_once(X[tr], y[tr], float(cval), max_iter, max_iter_cap, tol)
            all_conv &= fit.converged
            worst = max(worst, fit.n_iter)
            scores[f, c] = accuracy(y[ho], fit.model.predict(X[ho]))
    cv = scores.mean(axis=0)
    best = float(C[int(np.argmax(cv))])
    final = _fit_logistic_once(X, y, best, max_iter, max_iter_cap, tol)
    return LogisticProbe(best, C, cv, final, bool(all_conv), int(worst))


@dataclass(frozen=True)
class FixedLogistic:
    """Logistic probe at a fixed C, for controls and resampling diagnostics."""

    C: float
    max_iter: int = 200
    max_iter_cap: int = 12800
    tol: float = 1e-6

    def fit_predict(self, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray):
        fit = _fit_logistic_once(
            np.asarray(X_train, dtype=np.float64),
            np.asarray(y_train),
            self.C,
            self.max_iter,
            self.max_iter_cap,
            self.tol,
        )
        return fit.model.predict(np.asarray(X_test, dtype=np.float64))
