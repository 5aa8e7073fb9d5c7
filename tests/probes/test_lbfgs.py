"""`probes.lbfgs.fit_lbfgs_logistic` against scikit-learn's LogisticRegression(solver="lbfgs")."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression

from tacgen_lib.probes.lbfgs import fit_lbfgs_logistic


def problem(seed: int, n: int, p: int, k: int, noise: float = 1.0):
    """A standardised design whose labels (strings, k classes) depend on a few columns."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, p)) * (2.0 / np.sqrt(1.0 + np.arange(p)))
    X = (X - X.mean(0)) / X.std(0)
    score = X[:, : min(p, 3)] @ rng.standard_normal(min(p, 3)) + noise * rng.standard_normal(n)
    cuts = np.quantile(score, np.linspace(0, 1, k + 1)[1:-1])
    y = np.array([f"class_{i}" for i in np.digitize(score, cuts)], dtype=object)
    return X, y


def sklearn_fit(X, y, C, max_iter=12800, tol=1e-6):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return LogisticRegression(C=C, solver="lbfgs", max_iter=max_iter, tol=tol).fit(X, y)


@pytest.mark.parametrize(
    "n, p, k, C",
    [
        (32, 192, 2, 10.0),  # fewer rows than columns (the regime's labelled sets)
        (200, 20, 2, 1.0),
        (60, 120, 3, 0.1),
        (300, 40, 6, 1.0),  # the appearance check's six classes
        (300, 40, 6, 100.0),
    ],
)
def test_equals_scikit_learn(n, p, k, C):
    X, y = problem(n + p + k, n, p, k)
    ours = fit_lbfgs_logistic(X, y, C, max_iter=12800, tol=1e-6)
    ref = sklearn_fit(X, y, C)
    m = ours.model
    assert ours.converged
    assert list(m.classes_) == list(ref.classes_)
    assert m.coef_.shape == ref.coef_.shape and m.intercept_.shape == ref.intercept_.shape
    # the same iterates up to float rounding: the same iteration count here (small,
    # well-conditioned problems) and the same optimum within the stopping tolerance
    assert abs(int(m.n_iter_[0]) - int(ref.n_iter_[0])) <= 1
    np.testing.assert_allclose(m.predict_proba(X), ref.predict_proba(X), atol=1e-6)
    d_ours, d_ref = m.decision_function(X), ref.decision_function(X)
    np.testing.assert_allclose(d_ours, d_ref, atol=1e-5)
    margin = np.abs(d_ref) if k == 2 else np.abs(np.diff(np.sort(d_ref, axis=1)[:, -2:]))[:, 0]
    clear = margin > 1e-4
    assert (m.predict(X)[clear] == ref.predict(X)[clear]).all()


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(8, 80),
    p=st.integers(1, 60),
    k=st.integers(2, 4),
    log_c=st.floats(-2, 2),
)
def test_same_optimum_as_scikit_learn(seed, n, p, k, log_c):
    """Any shape and C: the optimum scikit-learn's lbfgs reaches, within its tolerance."""
    X, y = problem(seed, n, p, k, noise=0.5)
    if np.unique(y).size < 2:
        return
    C = float(10.0**log_c)
    ours = fit_lbfgs_logistic(X, y, C, max_iter=12800, tol=1e-8)
    ref = sklearn_fit(X, y, C, tol=1e-8)
    np.testing.assert_allclose(ours.model.predict_proba(X), ref.predict_proba(X), atol=1e-5)


def test_unconverged_at_the_cap_as_scikit_learn_warns():
    X, y = problem(3, 120, 30, 3, noise=0.1)
    ours = fit_lbfgs_logistic(X, y, 100.0, max_iter=3, tol=1e-10)
    assert not ours.converged and ours.n_iter == 3
    with pytest.warns(ConvergenceWarning):
        LogisticRegression(C=100.0, max_iter=3, tol=1e-10).fit(X, y)
    # and lbfgs's iterates do not depend on the budget: a longer run continues the same path
    longer = fit_lbfgs_logistic(X, y, 100.0, max_iter=12800, tol=1e-10)
    assert longer.converged and longer.n_iter > 3


def test_the_same_computation_twice_is_bit_identical():
    X, y = problem(5, 90, 50, 3)
    a = fit_lbfgs_logistic(X, y, 1.0, max_iter=12800, tol=1e-6).model
    b = fit_lbfgs_logistic(X, y, 1.0, max_iter=12800, tol=1e-6).model
    assert np.array_equal(a.coef_, b.coef_) and np.array_equal(a.intercept_, b.intercept_)


def test_refuses_a_single_class_and_mismatched_shapes():
    X = np.ones((4, 2))
    with pytest.raises(ValueError, match="one class"):
        fit_lbfgs_logistic(X, np.array(["a"] * 4), 1.0, max_iter=10, tol=1e-6)
    with pytest.raises(ValueError, match="do not match"):
        fit_lbfgs_logistic(X, np.array(["a", "b"]), 1.0, max_iter=10, tol=1e-6)
