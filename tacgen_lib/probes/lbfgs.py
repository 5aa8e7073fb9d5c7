"""scikit-learn's lbfgs logistic regression, one problem, without its per-iteration overhead.

`fit_lbfgs_logistic` minimises the objective ``LogisticRegression(solver="lbfgs")`` minimises
(scikit-learn's `_logistic_regression_path`): the mean loss over the rows plus
``||coef||^2 / (2 C n)``, intercept unpenalised, the half-binomial loss with one coefficient
vector for two classes and the half-multinomial loss with K vectors otherwise, from zero, by
the same call (``scipy.optimize.minimize``, L-BFGS-B, ``maxls`` 50, ``gtol`` = tol, ``ftol``
64 eps) over the same parameter layout (classes contiguous). Only the loss and gradient are
computed here, by four numpy calls instead of scikit-learn's generic `LinearModelLoss`.

Why: the probes fit thousands of small problems (CV folds x C, controls' refits) on rows of
32 to a few thousand, where an lbfgs iteration costs ~0.3 ms of scikit-learn's array-API
dispatch and input checks against ~0.1 ms of arithmetic. The iterates are scikit-learn's up to
float rounding (same iteration counts; decision values within ~1e-12 on well-conditioned
problems, within the solver's tolerance on ill-conditioned ones), tested against
``LogisticRegression`` in tests/probes/test_lbfgs.py; the speed-up is measured by
benchmarks/bench_probes.py. The batched objective of the controls
(`objective.LogisticObjective`) computes the same loss for B problems; at B = 1 its
generality costs more than scikit-learn's overhead (on a regime evaluation job), hence this
separate single-problem path.

The fitted model is a scikit-learn ``LogisticRegression`` with its fitted attributes set
(``classes_``, ``coef_``, ``intercept_``, ``n_iter_``, ``n_features_in_``): predictions and
probabilities are scikit-learn's own code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.special
from sklearn.linear_model import LogisticRegression

__all__ = ["LbfgsLogistic", "fit_lbfgs_logistic"]

_EPS = np.finfo(np.float64).eps


@dataclass(frozen=True)
class LbfgsLogistic:
    """One lbfgs fit: the fitted estimator, its iterations and whether lbfgs converged
    (scipy's status 0, the condition under which scikit-learn emits no ConvergenceWarning)."""

    model: LogisticRegression
    n_iter: int
    converged: bool


def _binary_loss(X: np.ndarray, t: np.ndarray, l2: float):
    """(loss, gradient) of the half-binomial objective at w = [coef, intercept]."""
    n, p = X.shape
    XT = np.ascontiguousarray(X.T)

    def loss_gradient(w: np.ndarray) -> tuple[float, np.ndarray]:
        coef = w[:p]
        z = X @ coef + w[p]
        loss = float((np.logaddexp(0.0, z) - t * z).sum()) / n + 0.5 * l2 * float(coef @ coef)
        r = (scipy.special.expit(z) - t) / n
        g = np.empty(p + 1)
        g[:p] = XT @ r + l2 * coef
        g[p] = r.sum()
        return loss, g

    return loss_gradient


def _multinomial_loss(X: np.ndarray, yi: np.ndarray, k: int, l2: float):
    """(loss, gradient) of the half-multinomial objective at w, the (k, p + 1) coefficients
    ravelled in Fortran order (scikit-learn's layout: a feature's k values contiguous)."""
    n, p = X.shape
    rows = np.arange(n)
    onehot = np.zeros((n, k))
    onehot[rows, yi] = 1.0 / n

    def loss_gradient(w: np.ndarray) -> tuple[float, np.ndarray]:
        W = w.reshape(k, p + 1, order="F")
        coef = W[:, :p]
        z = X @ coef.T + W[:, p]
        z -= z.max(axis=1, keepdims=True)  # softmax and logsumexp, shifted: no overflow
        e = np.exp(z)
        total = e.sum(axis=1)
        loss = float((np.log(total) - z[rows, yi]).sum()) / n
        loss += 0.5 * l2 * float((coef * coef).sum())
        r = e / (n * total[:, None]) - onehot
        g = np.empty((k, p + 1), order="F")
        g[:, :p] = r.T @ X + l2 * coef
        g[:, p] = r.sum(axis=0)
        return loss, g.ravel(order="F")

    return loss_gradient


def fit_lbfgs_logistic(
    X: np.ndarray, y: np.ndarray, C: float, *, max_iter: int, tol: float
) -> LbfgsLogistic:
    """``LogisticRegression(C=C, solver="lbfgs", max_iter=max_iter, tol=tol).fit(X, y)``, as
    scikit-learn solves it (module docstring), returning the fitted estimator.

    X: (n, p) float64 design (the probes pass it standardised); y: (n,) labels of at least
    two classes (sorted as ``np.unique``; the second of two is the positive class).
    """
    X = np.ascontiguousarray(X, dtype=np.float64)
    y = np.asarray(y)
    if X.ndim != 2 or y.shape != (X.shape[0],):
        raise ValueError(f"fit_lbfgs_logistic: X {X.shape} and y {y.shape} do not match")
    classes, yi = np.unique(y, return_inverse=True)
    if classes.size < 2:
        raise ValueError(
            f"fit_lbfgs_logistic: the training rows hold one class ({classes[0]!r}); "
            "a logistic probe needs at least 2 classes"
        )
    n, p = X.shape
    l2 = 1.0 / (C * n)
    if classes.size == 2:
        fun, w0 = _binary_loss(X, (yi == 1).astype(np.float64), l2), np.zeros(p + 1)
    else:
        k = classes.size
        fun, w0 = _multinomial_loss(X, yi, k, l2), np.zeros(k * (p + 1))
    res = scipy.optimize.minimize(
        fun,
        w0,
        method="L-BFGS-B",
        jac=True,
        options={"maxiter": max_iter, "maxls": 50, "gtol": tol, "ftol": 64 * _EPS},
    )
    if classes.size == 2:
        coef, intercept = res.x[:p][None, :].copy(), res.x[p:].copy()
    else:
        W = res.x.reshape(classes.size, p + 1, order="F")
        coef, intercept = W[:, :p].copy(), W[:, p].copy()
    n_iter = min(int(res.nit), int(max_iter))
    model = LogisticRegression(C=C, solver="lbfgs", max_iter=max_iter, tol=tol)
    model.classes_ = classes
    model.coef_, model.intercept_ = coef, intercept
    model.n_iter_ = np.array([n_iter], dtype=np.int32)
    model.n_features_in_ = p
    return LbfgsLogistic(model, n_iter, res.status == 0)
