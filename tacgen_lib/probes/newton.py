"""Newton's method for a binary logistic probe's cross-validation: one fold's whole C path.

`fit_logistic` chooses C by the held-out accuracy of K folds x the C grid. Where its folds are
solved one at a time (`logistic.fit_logistic`, the loop), a binary problem's fits are made here
instead of by lbfgs: the fold's C grid is walked from the strongest penalty to the weakest, each
fit started from the previous C's coefficients, by damped Newton steps. The objective is
scikit-learn's ``LogisticRegression(solver="lbfgs")``'s (`lbfgs.fit_lbfgs_logistic`): the
half-binomial loss summed over the rows plus ``||coef||^2 / (2 C)`` (its mean form times n),
intercept unpenalised; the stopping rule is lbfgs's (every component of the mean objective's
gradient within ``tol``), which Newton's quadratic convergence passes with the iterate much
nearer the minimiser than lbfgs's. So the held-out labels are lbfgs's wherever a row's
decision is not within lbfgs's own distance from the minimiser of 0 -- the agreement the
batched CV gives (`logistic._cv_scores_batched`).

Why: the generator's evaluation fits its nonlinear V baseline ([V, phi(V)], hundreds of
columns) by this CV thousands of times per job, and lbfgs needs hundreds of iterations at the
weak penalties on those ill-conditioned designs; a Newton path needs about ten steps per C, and
fewer when started from the neighbouring C. Each step solves with the Hessian ``X' D X +
I / C`` (plus the intercept's row and column, by its Schur complement): through the n x n
matrix ``I / C + S X X' S`` (Woodbury, S = sqrt(D)) where the fold has fewer rows than columns,
else the p x p one; a Cholesky factor either way (both positive definite). Measured against
the lbfgs loop by benchmarks/bench_probes.py; tested against scikit-learn's LogisticRegression
in tests/probes/test_newton.py.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.special

__all__ = ["NEWTON_MAX_STEPS", "NewtonFit", "newton_logistic_path"]

#: Newton steps a fit may take before it is reported unconverged (about ten are needed).
NEWTON_MAX_STEPS = 100
#: Armijo's sufficient-decrease fraction and the step halvings of the line search.
_ARMIJO, _HALVINGS = 1e-4, 50


@dataclass(frozen=True)
class NewtonFit:
    """One C of the path: coefficients on the design's columns, intercept, Newton steps taken
    and whether the gradient met the tolerance."""

    C: float
    coef: np.ndarray
    intercept: float
    n_iter: int
    converged: bool

    def decision(self, X: np.ndarray) -> np.ndarray:
        """Decision values X @ coef + intercept (the positive class where > 0, as
        scikit-learn's ``LogisticRegression.predict`` decides)."""
        return np.asarray(X, dtype=np.float64) @ self.coef + self.intercept


def newton_logistic_path(
    X: np.ndarray,
    positive: np.ndarray,
    C_path: Sequence[float],
    *,
    tol: float,
    max_steps: int = NEWTON_MAX_STEPS,
) -> list[NewtonFit]:
    """Minimisers of the L2 binary logistic objective (module docstring) at each C of
    ``C_path`` in the order given, each fit started from the previous one (the first from zero).

    X: (n, p) float64 design (the CV passes it standardised on these rows); positive: (n,)
    booleans, True for scikit-learn's positive class (the second of the two sorted classes).
    """
    X = np.ascontiguousarray(X, dtype=np.float64)
    t = np.asarray(positive, dtype=np.float64)
    if X.ndim != 2 or t.shape != (X.shape[0],):
        raise ValueError(f"newton_logistic_path: X {X.shape} and labels {t.shape} do not match")
    n, p = X.shape
    gram = X @ X.T if n < p else None  # the Woodbury form's X X', shared by every C
    w, b = np.zeros(p), 0.0
    fits = []
    for C in C_path:
        if not C > 0:
            raise ValueError(f"newton_logistic_path: C must be > 0, got {C}")
        w, b, n_iter, converged = _newton(X, t, 1.0 / float(C), w, b, gram, tol, max_steps)
        fits.append(NewtonFit(float(C), w.copy(), float(b), n_iter, converged))
    return fits


def _objective(X: np.ndarray, t: np.ndarray, lam: float, w: np.ndarray, b: float):
    """(summed objective, decision values) at (w, b)."""
    z = X @ w + b
    return float((np.logaddexp(0.0, z) - t * z).sum()) + 0.5 * lam * float(w @ w), z


def _newton(
    X: np.ndarray,
    t: np.ndarray,
    lam: float,
    w: np.ndarray,
    b: float,
    gram: np.ndarray | None,
    tol: float,
    max_steps: int,
) -> tuple[np.ndarray, float, int, bool]:
    """Damped Newton from (w, b) at penalty lam = 1 / C: (w, b, steps, converged)."""
    n = X.shape[0]
    f, z = _objective(X, t, lam, w, b)
    for step in range(max_steps + 1):
        prob = scipy.special.expit(z)
        r = prob - t
        g_w = X.T @ r + lam * w
        g_b = float(r.sum())
        if max(float(np.abs(g_w).max(initial=0.0)), abs(g_b)) <= tol * n:
            return w, b, step, True
        if step == max_steps:
            break
        d_w, d_b = _newton_direction(X, prob * (1.0 - prob), lam, g_w, g_b, gram)
        decrease = float(g_w @ d_w) + g_b * d_b
        size = 1.0
        for _ in range(_HALVINGS):
            f_new, z_new = _objective(X, t, lam, w - size * d_w, b - size * d_b)
            if f_new <= f - _ARMIJO * size * decrease:
                break
            size *= 0.5
        else:
            break  # no decrease along the Newton direction: at the floating-point floor
        w, b, f, z = w - size * d_w, b - size * d_b, f_new, z_new
    return w, b, step, False


def _newton_direction(
    X: np.ndarray,
    d: np.ndarray,
    lam: float,
    g_w: np.ndarray,
    g_b: float,
    gram: np.ndarray | None,
) -> tuple[np.ndarray, float]:
    """The Newton step H^-1 g for H = [[X' D X + lam I, X' d], [d' X, sum d]] (D = diag d):
    A = X' D X + lam I solved by Cholesky (through Woodbury's n x n form where ``gram`` = X X'
    is given), the intercept by A's Schur complement."""
    if gram is not None:
        s = np.sqrt(d)
        inner = s[:, None] * gram * s[None, :]
        inner[np.diag_indices_from(inner)] += lam
        factor = scipy.linalg.cho_factor(inner, lower=True, check_finite=False)

        def solve(q: np.ndarray) -> np.ndarray:
            back = scipy.linalg.cho_solve(factor, s * (X @ q), check_finite=False)
            return (q - X.T @ (s * back)) / lam

    else:
        A = X.T @ (d[:, None] * X)
        A[np.diag_indices_from(A)] += lam
        factor = scipy.linalg.cho_factor(A, lower=True, check_finite=False)

        def solve(q: np.ndarray) -> np.ndarray:
            return scipy.linalg.cho_solve(factor, q, check_finite=False)

    xd = X.T @ d
    u, v = solve(g_w), solve(xd)
    schur = float(d.sum() - xd @ v)  # > 0 in exact arithmetic: H is positive definite
    d_b = (g_b - float(xd @ u)) / max(schur, np.finfo(np.float64).tiny)
    return u - v * d_b, d_b
