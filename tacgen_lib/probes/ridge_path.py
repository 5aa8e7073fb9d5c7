"""Ridge regression for a whole grid of regularisers from ONE singular value decomposition of
the centred design (`ridge_path`; the intercept unpenalised, exactly as scikit-learn's
``Ridge(alpha=lam, fit_intercept=True)``), one regulariser's fit (`ridge_fixed`, through the
Gram matrix where that is safe), and the guarded eigendecomposition both the CV and the
refits use (`guarded_eigh`: None when squaring the singular values would lose directions the
smallest lambda needs, `GRAM_GUARD`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from tacgen_lib.probes.input_checks import check_features, check_lambdas, check_target

FLOAT64_EPS = np.finfo(np.float64).eps


GRAM_GUARD = 1e6


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
    keep = s > (max(X.shape) * FLOAT64_EPS * (s[0] if s.size else 0.0))
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
    if max(n, p) * FLOAT64_EPS * e_max * GRAM_GUARD <= lam:
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
    keep = s > (max(n, p) * FLOAT64_EPS * (s[0] if s.size else 0.0))
    u, s, vt = u[:, keep], s[keep], vt[keep]
    coef = vt.T @ ((s / (s**2 + lam))[:, None] * (u.T @ yc))
    intercept = y_mean - x_mean @ coef
    return (coef[:, 0], intercept[0], x_mean) if one else (coef, intercept, x_mean)


def guarded_eigh(
    m: np.ndarray, size: int, lam_min: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Eigenpairs (e, v) of the symmetric PSD `m` and the mask of eigenvalues above their error,
    or None when that error (``size * eps * e_max``) is too large for `lam_min` (`GRAM_GUARD`).
    """
    e, v = scipy.linalg.eigh(m, driver="evd", check_finite=False)  # evd: faster than numpy's
    err = size * FLOAT64_EPS * max(e[-1], 0.0)
    if err * GRAM_GUARD > lam_min:
        return None
    return e, v, e > err
