"""Probes: ridge path, CV selection, logistic probe, metrics, validation (vs sklearn / float64)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.optimize
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression, Ridge
from sklearn.metrics import accuracy_score, r2_score
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from tacgen_lib import probes


def ridge_reference(X, y, lam):
    """Float64 reference: least squares on the augmented system [Xc; sqrt(lam) I] b = [yc; 0]."""
    xm, ym = X.mean(axis=0), y.mean()
    p = X.shape[1]
    a = np.vstack([X - xm, np.sqrt(lam) * np.eye(p)])
    b = np.concatenate([y - ym, np.zeros(p)])
    coef = np.linalg.lstsq(a, b, rcond=None)[0]
    return coef, ym - xm @ coef


def regression_data(n, p, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, p)) * rng.uniform(0.5, 3.0, p) + rng.uniform(-4, 4, p)
    y = X[:, : max(1, p // 3)].sum(axis=1) + 0.5 * rng.standard_normal(n)
    return X, y


LAMBDAS = [1e-2, 1.0, 10.0, 100.0, 1e3]


@pytest.mark.parametrize("n,p", [(60, 12), (25, 70)])
def test_ridge_path_equals_sklearn_ridge(n, p):
    X, y = regression_data(n, p)
    path = probes.ridge_path(X, y, LAMBDAS)
    preds = path.predict(X)
    for i, lam in enumerate(LAMBDAS):
        ref = Ridge(alpha=lam).fit(X, y)
        np.testing.assert_allclose(path.coefs[i], ref.coef_, rtol=1e-9, atol=1e-11)
        assert path.intercepts[i] == pytest.approx(ref.intercept_, rel=1e-9, abs=1e-11)
        np.testing.assert_allclose(preds[i], ref.predict(X), rtol=1e-9, atol=1e-10)


def _hard_case(name):
    rng = np.random.default_rng(3)
    if name == "collinear_duplicated":
        base = rng.standard_normal((40, 6))
        X = np.column_stack([base, base[:, 0], 2.0 * base[:, 1] - base[:, 2], base[:, 3]])
        return X, base[:, 0] - base[:, 4] + 0.1 * rng.standard_normal(40), [1e-3, 1.0, 10.0]
    if name == "n_less_than_p":
        X = rng.standard_normal((15, 50))
        return X, X[:, 0] + 0.1 * rng.standard_normal(15), [1e-3, 1.0, 10.0]
    if name == "tiny_lambda":
        X = rng.standard_normal((30, 8))
        return X, X @ rng.standard_normal(8) + 0.1 * rng.standard_normal(30), [1e-8]
    if name == "scale_spread_1e6":
        X = rng.standard_normal((50, 6)) * np.array([1e-3, 1.0, 1e3, 1e-3, 1e3, 1.0])
        X += 1e3 * rng.standard_normal(6)
        return X, X[:, 0] * 1e3 + X[:, 2] * 1e-3 + rng.standard_normal(50), [1e-4, 1.0]
    raise KeyError(name)


@pytest.mark.parametrize(
    "case", ["collinear_duplicated", "n_less_than_p", "tiny_lambda", "scale_spread_1e6"]
)
def test_ridge_path_hard_cases_match_float64_reference_and_sklearn(case):
    X, y, lams = _hard_case(case)
    path = probes.ridge_path(X, y, lams)
    preds = path.predict(X)
    assert np.isfinite(path.coefs).all() and np.isfinite(preds).all()
    for i, lam in enumerate(lams):
        coef, icpt = ridge_reference(X, y, lam)
        scale = np.abs(coef).max()
        np.testing.assert_allclose(path.coefs[i], coef, rtol=1e-7, atol=1e-9 * scale)
        np.testing.assert_allclose(preds[i], X @ coef + icpt, rtol=1e-8, atol=1e-8)
        sk = Ridge(alpha=lam, solver="svd").fit(X, y)
        np.testing.assert_allclose(preds[i], sk.predict(X), rtol=1e-8, atol=1e-8)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(3, 30),
    p=st.integers(1, 30),
    log_lam=st.floats(-3, 3),
    seed=st.integers(0, 2**16),
)
def test_ridge_path_property_equals_sklearn(n, p, log_lam, seed):
    X, y = regression_data(n, p, seed)
    lam = 10.0**log_lam
    path = probes.ridge_path(X, y, [lam])
    ref = Ridge(alpha=lam, solver="svd").fit(X, y)
    np.testing.assert_allclose(path.predict(X)[0], ref.predict(X), rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(path.coefs[0], ref.coef_, rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize(
    "n,p,lams,dup,expected",
    [
        (80, 10, LAMBDAS, False, {"gram"}),  # primal: one p x p eigh per fold
        (40, 90, LAMBDAS, False, {"deletion"}),  # dual: one eigh for all folds
        (40, 90, LAMBDAS, True, {"deletion"}),  # duplicated rows: null space of the Gram
        (40, 6, [1e-9, 1.0], False, {"svd"}),  # lambda below the Gram's resolution
        (30, 60, [1e-9, 1.0], False, {"svd"}),
    ],
)
def test_select_lambda_cv_equals_gridsearchcv(n, p, lams, dup, expected):
    X, y = regression_data(n, p, seed=5)
    if dup:
        X[1::4] = X[0::4]  # rows 4k+1 duplicate rows 4k, with other targets
    sel = probes.select_lambda_cv(X, y, lams, n_folds=5, seed=11)
    cv = [(np.setdiff1d(np.arange(n), f), f) for f in sel.folds]
    gs = GridSearchCV(Ridge(solver="svd"), {"alpha": lams}, cv=cv).fit(X, y)
    assert sel.lam == gs.best_params_["alpha"]
    np.testing.assert_allclose(sel.cv_scores, gs.cv_results_["mean_test_score"], rtol=1e-7)
    assert set(sel.solver) == expected


def test_folds_are_deterministic_partitions():
    a = probes.make_folds(103, 5, seed=4)
    b = probes.make_folds(103, 5, seed=4)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert np.array_equal(np.sort(np.concatenate(a)), np.arange(103))
    labels = np.repeat([0, 1, 2], [50, 30, 23])
    strat = probes.make_folds(103, 5, seed=4, labels=labels)
    for f in strat:
        assert set(np.bincount(labels[f], minlength=3)) <= {4, 5, 6, 10, 11}


def test_fit_ridge_probe_refit_equals_sklearn():
    X, y = regression_data(90, 20, seed=2)
    probe = probes.fit_ridge_probe(X[:70], y[:70], LAMBDAS, seed=1)
    ref = Ridge(alpha=probe.lam).fit(X[:70], y[:70])
    np.testing.assert_allclose(probe.predict(X[70:]), ref.predict(X[70:]), rtol=1e-9)
    fixed = probes.FixedRidge(probe.lam).fit_predict(X[:70], y[:70], X[70:])
    np.testing.assert_allclose(fixed, ref.predict(X[70:]), rtol=1e-9)


@pytest.mark.parametrize(
    "n,p,lam", [(20, 45, 3.0), (45, 20, 3.0), (45, 20, 1e-9)]
)  # dual Cholesky, primal Cholesky, SVD fallback for a lambda the Gram cannot resolve
def test_ridge_fixed_multi_target_equals_sklearn(n, p, lam):
    X, y = regression_data(n, p, seed=8)
    Y = np.column_stack([y, y[::-1], 2 * y + 1])
    coef, icpt, _ = probes.ridge_fixed(X, Y, lam)
    ref = Ridge(alpha=lam, solver="svd").fit(X, Y)
    np.testing.assert_allclose(coef.T, ref.coef_, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(icpt, ref.intercept_, rtol=1e-8)


def test_metrics_equal_sklearn_and_constant_target_rule():
    rng = np.random.default_rng(0)
    y, p = rng.standard_normal(30), rng.standard_normal(30)
    assert probes.r2(y, p) == pytest.approx(r2_score(y, p), rel=1e-12)
    labels = rng.integers(0, 3, 30)
    guess = rng.integers(0, 3, 30)
    assert probes.accuracy(labels, guess) == accuracy_score(labels, guess)
    const = np.full(7, 0.1)  # mean of 0.1s rounds; constancy must still be recognised
    assert probes.r2(const, const) == 1.0
    assert probes.r2(const, const + 1.0) == 0.0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_feature_names_the_sample(bad):
    X, y = regression_data(12, 4)
    X[7, 2] = bad
    ids = [f"p-{i:04d}" for i in range(12)]
    with pytest.raises(ValueError, match=r"sample_id 'p-0007'.*column 2"):
        probes.ridge_path(X, y, [1.0], sample_ids=ids)
    with pytest.raises(ValueError, match=r"sample_id 'p-0007'"):
        probes.select_lambda_cv(X, y, [1.0], sample_ids=ids)
    with pytest.raises(ValueError, match=r"sample_id 'p-0007'"):
        probes.fit_logistic(X, (y > 0).astype(int), [1.0], seed=0, sample_ids=ids)


def test_shape_mismatches_are_named():
    X, y = regression_data(12, 4)
    with pytest.raises(ValueError, match=r"y: 11 targets for 12 feature rows"):
        probes.ridge_path(X, y[:11], [1.0])
    with pytest.raises(ValueError, match=r"12 rows but 3 sample_ids"):
        probes.ridge_path(X, y, [1.0], sample_ids=["a", "b", "c"])
    path = probes.ridge_path(X, y, [1.0])
    with pytest.raises(ValueError, match=r"X_new: 5 features, the path was fitted on 4"):
        path.predict(np.ones((2, 5)))
    with pytest.raises(ValueError, match=r"lambdas"):
        probes.ridge_path(X, y, [0.0])


def separable_three_class(n_per=30, seed=0):
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0, 0.0], [6.0, 0.0, 0.0], [0.0, 6.0, 0.0]])
    X = np.vstack([c + rng.uniform(-1, 1, (n_per, 3)) for c in centres])
    X = np.column_stack([X, 1e4 * rng.standard_normal(len(X))])  # badly scaled nuisance column
    return X, np.repeat(np.array([0, 1, 2]), n_per)


def logistic_reference_proba(X, y, C):
    """Float64 reference: standardise, minimise C * sum CE + 0.5 ||W||^2 (bias free) by BFGS."""
    mu, sd = X.mean(axis=0), X.std(axis=0)
    Z = (X - mu) / sd
    k, p = 3, Z.shape[1]
    onehot = np.eye(k)[y]

    def f(theta):
        W, b = theta[: k * p].reshape(k, p), theta[k * p :]
        logits = Z @ W.T + b
        m = logits.max(axis=1, keepdims=True)
        lse = m[:, 0] + np.log(np.exp(logits - m).sum(axis=1))
        prob = np.exp(logits - lse[:, None])
        loss = C * np.sum(lse - (logits * onehot).sum(axis=1)) + 0.5 * np.sum(W**2)
        g = prob - onehot
        grad = np.concatenate([(C * g.T @ Z + W).ravel(), C * g.sum(axis=0)])
        return loss, grad

    res = scipy.optimize.minimize(
        f, np.zeros(k * p + k), jac=True, method="BFGS", options={"gtol": 1e-10}
    )
    W, b = res.x[: k * p].reshape(k, p), res.x[k * p :]
    logits = Z @ W.T + b
    e = np.exp(logits - logits.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def test_logistic_separable_converges_without_warnings_and_matches_reference():
    X, y = separable_three_class()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any swallowed-then-leaked warning fails the test
        probe = probes.fit_logistic(X, y, [0.1, 1.0, 10.0], seed=0)
    assert probe.converged and probe.cv_converged
    assert 0 < probe.n_iter < probe.fit.max_iter
    assert probes.accuracy(y, probe.predict(X)) == 1.0
    ref = logistic_reference_proba(X, y, probe.C)
    np.testing.assert_allclose(probe.predict_proba(X), ref, atol=1e-4)


def test_logistic_raises_max_iter_instead_of_swallowing():
    X, y = separable_three_class(seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        probe = probes.fit_logistic(X, y, [10.0], seed=0, max_iter=2)
    assert probe.converged and probe.fit.max_iter > 2
    with pytest.warns(ConvergenceWarning, match="did not converge within max_iter=2"):
        capped = probes.fit_logistic(X, y, [10.0], seed=0, max_iter=1, max_iter_cap=2)
    assert not capped.converged and not capped.cv_converged


def test_logistic_C_selection_equals_gridsearchcv_on_same_folds():
    rng = np.random.default_rng(4)
    X = rng.standard_normal((120, 6))
    y = np.digitize(X[:, 0] + X[:, 1] + 0.8 * rng.standard_normal(120), [-0.7, 0.7])
    grid = [1e-3, 1e-2, 0.1, 1.0]
    probe = probes.fit_logistic(X, y, grid, seed=3)
    folds = probes.make_folds(120, 5, 3, labels=y)
    cv = [(np.setdiff1d(np.arange(120), f), f) for f in folds]
    pipe = Pipeline([("s", StandardScaler()), ("m", LogisticRegression(max_iter=10000, tol=1e-6))])
    gs = GridSearchCV(pipe, {"m__C": grid}, cv=cv).fit(X, y)
    assert probe.C == gs.best_params_["m__C"]
    np.testing.assert_allclose(probe.cv_scores, gs.cv_results_["mean_test_score"], atol=1e-12)
