"""Probes: ridge path, CV selection, logistic probe, metrics, validation (vs sklearn / float64)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.optimize
from hypothesis import given, settings
from hypothesis import strategies as st
from probe_worlds import probe_settings
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression, Ridge
from sklearn.metrics import accuracy_score, r2_score
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from tacgen_lib.probes import logistic
from tacgen_lib.probes.batched import block_basis, fit_logistic_batch
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.logistic import fit_logistic
from tacgen_lib.probes.metrics import accuracy, r2
from tacgen_lib.probes.objective import DesignBlock, standardise_block
from tacgen_lib.probes.ridge import FixedRidge, fit_ridge_probe
from tacgen_lib.probes.ridge_cv import select_lambda_cv
from tacgen_lib.probes.ridge_path import ridge_fixed, ridge_path


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
    path = ridge_path(X, y, LAMBDAS)
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
    path = ridge_path(X, y, lams)
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
    path = ridge_path(X, y, [lam])
    ref = Ridge(alpha=lam, solver="svd").fit(X, y)
    np.testing.assert_allclose(path.predict(X)[0], ref.predict(X), rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(path.coefs[0], ref.coef_, rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize(
    "n,p,lams,dup,expected",
    [
        (80, 10, LAMBDAS, False, {"deletion"}),  # primal: one p x p eigh for all folds
        (80, 10, LAMBDAS, True, {"deletion"}),  # primal with duplicated rows
        (60, 45, LAMBDAS, False, {"deletion"}),  # primal, p close to the fold-train rows
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
    sel = select_lambda_cv(X, y, lams, n_folds=5, seed=11, repeats=1)
    cv = [(np.setdiff1d(np.arange(n), f), f) for f in sel.folds]
    gs = GridSearchCV(Ridge(solver="svd"), {"alpha": lams}, cv=cv).fit(X, y)
    assert sel.lam == gs.best_params_["alpha"]
    np.testing.assert_allclose(sel.cv_scores, gs.cv_results_["mean_test_score"], rtol=1e-7)
    assert set(sel.solver) == expected


def test_folds_are_deterministic_partitions():
    a = make_folds(103, 5, seed=4)
    b = make_folds(103, 5, seed=4)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert np.array_equal(np.sort(np.concatenate(a)), np.arange(103))
    labels = np.repeat([0, 1, 2], [50, 30, 23])
    strat = make_folds(103, 5, seed=4, labels=labels)
    for f in strat:
        assert set(np.bincount(labels[f], minlength=3)) <= {4, 5, 6, 10, 11}


def test_fit_ridge_probe_refit_equals_sklearn():
    X, y = regression_data(90, 20, seed=2)
    probe = fit_ridge_probe(X[:70], y[:70], LAMBDAS, seed=1, repeats=1, n_folds=5)
    ref = Ridge(alpha=probe.lam).fit(X[:70], y[:70])
    np.testing.assert_allclose(probe.predict(X[70:]), ref.predict(X[70:]), rtol=1e-9)
    fixed = FixedRidge(probe.lam).fit_predict(X[:70], y[:70], X[70:])
    np.testing.assert_allclose(fixed, ref.predict(X[70:]), rtol=1e-9)


@pytest.mark.parametrize(
    "n,p,lam", [(20, 45, 3.0), (45, 20, 3.0), (45, 20, 1e-9)]
)  # dual Cholesky, primal Cholesky, SVD fallback for a lambda the Gram cannot resolve
def test_ridge_fixed_multi_target_equals_sklearn(n, p, lam):
    X, y = regression_data(n, p, seed=8)
    Y = np.column_stack([y, y[::-1], 2 * y + 1])
    coef, icpt, _ = ridge_fixed(X, Y, lam)
    ref = Ridge(alpha=lam, solver="svd").fit(X, Y)
    np.testing.assert_allclose(coef.T, ref.coef_, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(icpt, ref.intercept_, rtol=1e-8)


def test_metrics_equal_sklearn_and_constant_target_rule():
    rng = np.random.default_rng(0)
    y, p = rng.standard_normal(30), rng.standard_normal(30)
    assert r2(y, p) == pytest.approx(r2_score(y, p), rel=1e-12)
    labels = rng.integers(0, 3, 30)
    guess = rng.integers(0, 3, 30)
    assert accuracy(labels, guess) == accuracy_score(labels, guess)
    const = np.full(7, 0.1)  # mean of 0.1s rounds; constancy must still be recognised
    assert r2(const, const) == 1.0
    assert r2(const, const + 1.0) == 0.0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_feature_names_the_sample(bad):
    X, y = regression_data(12, 4)
    X[7, 2] = bad
    ids = [f"p-{i:04d}" for i in range(12)]
    with pytest.raises(ValueError, match=r"sample_id 'p-0007'.*column 2"):
        ridge_path(X, y, [1.0], sample_ids=ids)
    with pytest.raises(ValueError, match=r"sample_id 'p-0007'"):
        select_lambda_cv(X, y, [1.0], sample_ids=ids, repeats=1, seed=0, n_folds=5)
    with pytest.raises(ValueError, match=r"sample_id 'p-0007'"):
        fit_logistic(X, (y > 0).astype(int), [1.0], seed=0, sample_ids=ids, n_folds=5, repeats=1)


def test_shape_mismatches_are_named():
    X, y = regression_data(12, 4)
    with pytest.raises(ValueError, match=r"y: 11 targets for 12 feature rows"):
        ridge_path(X, y[:11], [1.0])
    with pytest.raises(ValueError, match=r"12 rows but 3 sample_ids"):
        ridge_path(X, y, [1.0], sample_ids=["a", "b", "c"])
    path = ridge_path(X, y, [1.0])
    with pytest.raises(ValueError, match=r"X_new: 5 features, the path was fitted on 4"):
        path.predict(np.ones((2, 5)))
    with pytest.raises(ValueError, match=r"lambdas"):
        ridge_path(X, y, [0.0])


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
        probe = fit_logistic(X, y, [0.1, 1.0, 10.0], seed=0, n_folds=5, repeats=1)
    assert probe.converged and probe.cv_converged
    assert 0 < probe.n_iter < probe.fit.max_iter
    assert accuracy(y, probe.predict(X)) == 1.0
    ref = logistic_reference_proba(X, y, probe.C)
    np.testing.assert_allclose(probe.predict_proba(X), ref, atol=1e-4)


def test_logistic_raises_max_iter_instead_of_swallowing():
    X, y = separable_three_class(seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        probe = fit_logistic(X, y, [10.0], seed=0, max_iter=2, n_folds=5, repeats=1)
    assert probe.converged and probe.fit.max_iter > 2
    with pytest.warns(ConvergenceWarning, match="did not converge within max_iter=2"):
        capped = fit_logistic(
            X, y, [10.0], seed=0, max_iter=1, max_iter_cap=2, n_folds=5, repeats=1
        )
    assert not capped.converged and not capped.cv_converged


def test_logistic_C_selection_equals_gridsearchcv_on_same_folds():
    rng = np.random.default_rng(4)
    X = rng.standard_normal((120, 6))
    y = np.digitize(X[:, 0] + X[:, 1] + 0.8 * rng.standard_normal(120), [-0.7, 0.7])
    grid = [1e-3, 1e-2, 0.1, 1.0]
    probe = fit_logistic(X, y, grid, seed=3, n_folds=5, repeats=1)
    folds = make_folds(120, 5, 3, labels=y)
    cv = [(np.setdiff1d(np.arange(120), f), f) for f in folds]
    pipe = Pipeline([("s", StandardScaler()), ("m", LogisticRegression(max_iter=10000, tol=1e-6))])
    gs = GridSearchCV(pipe, {"m__C": grid}, cv=cv).fit(X, y)
    # the probe's CV solves its folds together (batched solver), GridSearchCV one fit at a
    # time: solvers stopped at tol 1e-6, whose held-out labels may differ only on rows whose
    # decision is within their agreement radius of 0 (`cv_ambiguity`, whose own loop is
    # scikit-learn's again; no such row here, so the scores must be equal)
    loop, ambiguous, n_held_out = cv_ambiguity(X, y, folds, grid, tol=1e-6)
    assert_cv_agrees(loop.mean(axis=0), gs.cv_results_["mean_test_score"], ambiguous, n_held_out)
    slack = assert_cv_agrees(
        probe.cv_scores, gs.cv_results_["mean_test_score"], ambiguous, n_held_out
    )
    if clear_best(gs.cv_results_["mean_test_score"], slack):
        assert probe.C == gs.best_params_["m__C"]


@pytest.mark.parametrize(
    ("n", "p", "classes", "grid"),
    [
        (400, 40, 2, [0.1, 1.0, 10.0]),  # binary, the default C grid
        (300, 60, 3, [0.1, 1.0, 10.0]),  # multinomial
        (75, 60, 2, [0.01, 1.0, 100.0]),  # folds keep barely more rows (60) than features
    ],
)
def test_batched_cv_gives_the_scikit_learn_loops_scores(n, p, classes, grid, monkeypatch):
    """The CV's folds solved together (`cv_batches`) and one fold at a time (on two classes a
    Newton path per fold, `newton`; on more scikit-learn's lbfgs per C) both give scikit-learn's
    one-fit-at-a-time held-out scores up to held-out rows whose decision is within the solvers'
    agreement radius of 0 (`cv_ambiguity`), hence its C where no such row can change the
    choice, and at the same C the same final fit (always scikit-learn's: bit for bit)."""
    rng = np.random.default_rng(n + p)
    X = rng.standard_normal((n, p)) * rng.uniform(0.1, 30.0, p) + rng.uniform(-50, 50, p)
    signal = X[:, :3] @ np.array([1.0, -0.5, 0.25]) / X[:, :3].std(0).mean()
    y = np.digitize(
        signal + rng.standard_normal(n), np.quantile(signal, np.linspace(0, 1, classes + 1)[1:-1])
    )
    labels = np.array(["hard", "medium", "soft"], dtype=object)[y]  # labels as the probes see them
    folds = make_folds(n, 5, 7, labels=labels)
    assert logistic.cv_batches(X.shape, folds)
    batched = fit_logistic(X, labels, grid, seed=7, n_folds=5, repeats=1)
    monkeypatch.setattr(logistic, "cv_batches", lambda shape, folds: False)
    loop = fit_logistic(X, labels, grid, seed=7, n_folds=5, repeats=1)
    assert batched.cv_converged and loop.cv_converged
    # two solvers stopped at tol 1e-6 (their decisions differ by up to ~3e-2 here, on
    # held-out rows as close as ~1e-3 to the boundary): the loop's own fold fits, the same
    # computation as `loop` (bit for bit), and the rows the batched CV may label otherwise
    folds_loop, ambiguous, n_held_out = cv_ambiguity(X, labels, folds, grid, tol=1e-6)
    reference = folds_loop.mean(axis=0)
    if classes > 2:  # the loop is scikit-learn's fits themselves
        np.testing.assert_array_equal(reference, loop.cv_scores)
    assert_cv_agrees(loop.cv_scores, reference, ambiguous, n_held_out)
    slack = assert_cv_agrees(batched.cv_scores, reference, ambiguous, n_held_out)
    assert ambiguous.sum() < ambiguous.size * n_held_out.min() / 4  # the radius is informative
    if clear_best(reference, slack):
        assert batched.C == loop.C == float(grid[int(np.argmax(reference))])
    if batched.C == loop.C:  # the same final scikit-learn fit: the same computation
        np.testing.assert_array_equal(batched.predict(X), loop.predict(X))


def test_folds_the_batched_solve_leaves_unfinished_are_refitted_by_scikit_learn():
    """Past its iteration budget the batched CV hands each unfinished fold to scikit-learn:
    with a budget of 1 every fold is refitted, and the CV is scikit-learn's fold fits exactly."""
    rng = np.random.default_rng(5)
    X = rng.standard_normal((200, 8))
    y = np.where(X[:, 0] + 0.5 * rng.standard_normal(200) > 0, "hard", "soft").astype(object)
    folds = make_folds(200, 5, 1, labels=y)
    C = np.array([0.1, 1.0, 10.0])
    scores, converged, _ = logistic._cv_scores_batched(X, y, folds, C, 12800, 12800, 1e-6, budget=1)
    one_at_a_time = [
        [logistic._fold_score(X, y, ho, float(c), 12800, 12800, 1e-6)[0] for c in C] for ho in folds
    ]
    np.testing.assert_array_equal(scores, one_at_a_time)
    assert converged


def test_batched_false_is_the_scikit_learn_loop(monkeypatch):
    """`batched=False` never calls the batched solver and is the loop's computation (bit for
    bit: the same fold fits), on a shape `cv_batches` would batch."""
    rng = np.random.default_rng(11)
    X = rng.standard_normal((300, 12))
    y = np.where(X[:, 0] + 0.5 * rng.standard_normal(300) > 0, "hard", "soft").astype(object)
    assert logistic.cv_batches(X.shape, make_folds(300, 5, 3, labels=y))

    def refuse(*args, **kwargs):
        raise AssertionError("the batched solver ran")

    monkeypatch.setattr(logistic, "fit_logistic_batch", refuse)
    unbatched = fit_logistic(X, y, [0.1, 1.0, 10.0], seed=3, batched=False, n_folds=5, repeats=1)
    monkeypatch.setattr(logistic, "cv_batches", lambda shape, folds: False)
    loop = fit_logistic(X, y, [0.1, 1.0, 10.0], seed=3, n_folds=5, repeats=1)
    np.testing.assert_array_equal(unbatched.cv_scores, loop.cv_scores)
    assert unbatched.C == loop.C
    np.testing.assert_array_equal(unbatched.predict_proba(X), loop.predict_proba(X))


def test_nonlinear_baseline_fits_its_logistic_cv_one_fold_at_a_time(monkeypatch):
    """On V + an RBF Nystroem map the batched solve rarely finishes within its budget: the
    nonlinear baseline never starts it."""
    from tacgen_lib.generate.baselines import nonlinear_baseline

    def refuse(*args, **kwargs):
        raise AssertionError("the batched solver ran")

    monkeypatch.setattr(logistic, "fit_logistic_batch", refuse)
    rng = np.random.default_rng(2)
    v = rng.standard_normal((200, 6))
    y = np.where(np.sin(2 * v[:, 0]) + 0.3 * rng.standard_normal(200) > 0, "a", "b").astype(object)
    settings = probe_settings("logistic", (1.0,), (0.1, 1.0), folds=3, bootstrap=100, seed=0)
    nl = nonlinear_baseline(
        v[:150], v[150:], y[:150], settings, gammas=[1.0], n_components=6, seed=0
    )
    assert len(nl.probe.pred_test) == 50


def test_cv_with_fewer_rows_than_features_per_fold_is_not_batched():
    folds = make_folds(120, 5, 0)  # 96 training rows per fold
    assert not logistic.cv_batches((120, 960), folds)  # the density probe's shape
    assert logistic.cv_batches((1200, 384), make_folds(1200, 5, 0))  # the hardness probe's


# --------------------------------------------------------------------------- ridge grid refit


@pytest.mark.parametrize("n,p", [(60, 12), (25, 70)])  # primal and dual deletion paths
def test_ridge_probe_grid_refit_equals_sklearn_at_every_lambda(n, p):
    X, y = regression_data(n + 15, p, seed=9)
    probe = fit_ridge_probe(X[:n], y[:n], LAMBDAS, seed=2, repeats=1, n_folds=5)
    assert set(probe.selection.solver) == {"deletion"}
    grid = probe.predict_grid(X[n:])
    for i, lam in enumerate(LAMBDAS):
        ref = Ridge(alpha=lam, solver="svd").fit(X[:n], y[:n])
        np.testing.assert_allclose(grid[i], ref.predict(X[n:]), rtol=1e-8, atol=1e-10)
    # the same coefficients, applied by another product (the grid's (L, p) x (p, m) against
    # (m, p) x (p,)): float64 unit roundoff 1.1e-16 x p <= 70 terms x sum|x_j b_j| / |pred|
    # <= 24 on these rows -> <= 2e-13 -> rtol 1e-12
    np.testing.assert_allclose(grid[LAMBDAS.index(probe.lam)], probe.predict(X[n:]), rtol=1e-12)


# --------------------------------------------------------------------------- batched logistic


def objective_gradient(Z, y, sw, coef, intercept, C, classes):
    """Plain float64 gradient of scikit-learn's lbfgs objective at (coef (p, K'), intercept).

    sum_i sw_i loss_i / S + ||coef||^2 / (2 C S); sigmoid for two classes, softmax otherwise.
    """
    S = sw.sum()
    yi = np.searchsorted(classes, y)
    m = Z @ coef + intercept
    if coef.shape[1] == 1:
        d = 1.0 / (1.0 + np.exp(-m[:, 0])) - (yi == 1)
        d = d[:, None]
    else:
        e = np.exp(m - m.max(axis=1, keepdims=True))
        d = e / e.sum(axis=1, keepdims=True) - np.eye(coef.shape[1])[yi]
    d = d * (sw / S)[:, None]
    return np.concatenate([(Z.T @ d + coef / (C * S)).ravel(), d.sum(axis=0)])


def sklearn_fit(Z, y, C, sw=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return LogisticRegression(C=C, tol=1e-12, max_iter=100000).fit(Z, y, sample_weight=sw)


def gradient_of(Z, y, sw, C, shape, classes):
    """theta = [coef (p, K') raveled, intercept (K')] -> `objective_gradient` there."""
    size = shape[0] * shape[1]

    def grad(theta):
        return objective_gradient(Z, y, sw, theta[:size].reshape(shape), theta[size:], C, classes)

    return grad


def objective_hessian(grad, theta, k):
    """The objective's Hessian at theta (finite differences of the float64 gradient) in an
    orthonormal basis q of the parameters without the softmax's intercept-shift null
    direction (k > 1; q = identity for k = 1): (H, q), H symmetric."""
    h = 1e-5
    hess = np.array(
        [(grad(theta + h * e) - grad(theta - h * e)) / (2 * h) for e in np.eye(theta.size)]
    )
    q = np.eye(theta.size)
    if k > 1:  # drop the intercept-shift null direction of the softmax
        shift = np.zeros(theta.size)
        shift[-k:] = 1 / np.sqrt(k)
        q = np.linalg.qr(np.column_stack([shift, q]))[0][:, 1 : theta.size]
        hess = q.T @ hess @ q
    return 0.5 * (hess + hess.T), q


def min_curvature(grad, theta, k):
    """The smallest eigenvalue mu of the objective's Hessian at theta (`objective_hessian`)."""
    mu = np.linalg.eigvalsh(objective_hessian(grad, theta, k)[0])[0]
    assert mu > 0
    return mu


def cv_ambiguity(X, y, folds, grid, tol):
    """The CV's scikit-learn loop, fold by fold (as `logistic._fold_score`), and which held-out
    labels another solver stopped at the same tolerance may give otherwise.

    Returns (scores, ambiguous, n_held_out): scores (folds, C) of the loop's fits; ambiguous
    (folds, C) the held-out rows whose decision a (|decision| for two classes; for more, the
    gap of the two largest logits, which picks the label) lies within the solvers' agreement
    radius of 0. The radius: a is linear in theta, a = w . theta; two stops of one objective
    with Hessian H >= mu I at gradients g_a, g_b differ by theta_a - theta_b ~ H^-1 (g_a - g_b),
    so |w . (theta_a - theta_b)| <= 2 sqrt(w H^-1 w) (||g_a|| + ||g_b||) / sqrt(mu) (Cauchy-
    Schwarz in the H^-1 metric; factor 2: the Hessian's variation, as `assert_same_optimum`),
    with ||g_loop|| measured and the other solver's ||g|| <= sqrt(P) tol (its stopping rule,
    max |g| <= tol). Only ambiguous rows may flip, each moving its fold's score by 1 / n_ho.
    """
    n = X.shape[0]
    scores = np.zeros((len(folds), len(grid)))
    ambiguous = np.zeros((len(folds), len(grid)), dtype=int)
    for f, ho in enumerate(folds):
        tr = np.setdiff1d(np.arange(n), ho, assume_unique=True)
        for c, C in enumerate(grid):
            fit = logistic.fit_logistic_once(X[tr], y[tr], float(C), 12800, 12800, tol)
            scaler, model = fit.model.named_steps["standardise"], fit.model.named_steps["logistic"]
            scores[f, c] = accuracy(y[ho], fit.model.predict(X[ho]))
            coef, icpt = model.coef_.T, model.intercept_
            p, k = coef.shape
            if k > 1:  # softmax intercepts are defined up to a shift: centre them
                icpt = icpt - icpt.mean()
            grad = gradient_of(
                scaler.transform(X[tr]),
                y[tr],
                np.ones(len(tr)),
                float(C),
                coef.shape,
                model.classes_,
            )
            theta = np.concatenate([coef.ravel(), icpt])
            hess, q = objective_hessian(grad, theta, k)
            mu = np.linalg.eigvalsh(hess)[0]
            assert mu > 0
            g = 2 * (np.linalg.norm(grad(theta)) + np.sqrt(theta.size) * tol) / np.sqrt(mu)
            z = np.column_stack([scaler.transform(X[ho]), np.ones(len(ho))])
            d = fit.model.decision_function(X[ho])
            if k == 1:  # theta = [coef (p), intercept]: the decision's w is (z, 1)
                margin, w = np.abs(d), z
            else:  # theta = [coef (p, k) row-major, intercepts (k)]: the top-two logit gap
                order = np.argsort(d, axis=1)
                top, second = order[:, -1], order[:, -2]
                margin = d[np.arange(len(ho)), top] - d[np.arange(len(ho)), second]
                w = np.zeros((len(ho), p + 1, k))
                w[np.arange(len(ho)), :, top] = z
                w[np.arange(len(ho)), :, second] -= z
                w = np.concatenate([w[:, :p].reshape(len(ho), -1), w[:, p]], axis=1)
            wq = w @ q
            radius = g * np.sqrt(np.einsum("ij,ij->i", wq, np.linalg.solve(hess, wq.T).T))
            ambiguous[f, c] = int(np.sum(margin <= radius))
    return scores, ambiguous, np.array([len(ho) for ho in folds])


def assert_cv_agrees(got, ref, ambiguous, n_held_out):
    """CV scores (C,) of another solver against the loop's: equal, except that each
    ambiguous held-out row (`cv_ambiguity`) may move its fold's share 1 / (K n_held_out)."""
    slack = (ambiguous / n_held_out[:, None]).mean(axis=0)
    assert np.all(np.abs(np.asarray(got) - np.asarray(ref)) <= slack + 1e-12), (got, ref, slack)
    return slack


def clear_best(scores, slack):
    """Whether no set of ambiguous rows can change the loop's choice of C: none exists (the
    scores are then equal, ties and their first-C rule included), or its best C beats every
    other C by more than the two slacks."""
    best = int(np.argmax(scores))
    return not slack.any() or all(
        scores[best] - slack[best] > scores[j] + slack[j] for j in range(len(scores)) if j != best
    )


def assert_same_optimum(Z, y, sw, C, got_coef, got_icpt, ref, classes):
    """Parameters agree within the strong-convexity bound of the two gradients:
    ||theta_a - theta_b|| <= (||g_a|| + ||g_b||) / mu, mu = the smallest Hessian eigenvalue
    (finite differences of the float64 gradient at the reference; the intercept is
    unpenalised, so mu comes from the loss there), with a factor 2 for the Hessian's
    variation between points this close."""
    ref_coef, ref_icpt = ref.coef_.T, ref.intercept_
    if ref_coef.shape[1] > 1:  # softmax intercepts are defined up to a shift: centre them
        ref_icpt = ref_icpt - ref_icpt.mean()
        got_icpt = got_icpt - got_icpt.mean()
    shape = ref_coef.shape

    def grad(theta):
        return objective_gradient(
            Z, y, sw, theta[: ref_coef.size].reshape(shape), theta[ref_coef.size :], C, classes
        )

    theta = np.concatenate([ref_coef.ravel(), ref_icpt])
    mu = min_curvature(grad, theta, ref_coef.shape[1])
    g_got = grad(np.concatenate([got_coef.ravel(), got_icpt]))
    g_ref = grad(theta)
    bound = 2 * (np.linalg.norm(g_got) + np.linalg.norm(g_ref)) / mu
    diff = np.concatenate([(got_coef - ref_coef).ravel(), got_icpt - ref_icpt])
    assert np.linalg.norm(diff) <= bound + 1e-12
    return bound


@pytest.mark.parametrize("n_classes,C", [(2, 0.1), (2, 10.0), (3, 1.0)])
def test_logistic_batch_equals_sklearn_on_permuted_targets(n_classes, C):
    rng = np.random.default_rng(n_classes)
    X = rng.standard_normal((90, 7)) * rng.uniform(0.1, 20, 7) + rng.uniform(-50, 50, 7)
    y = np.digitize(X[:, 0] / X[:, 0].std() + rng.standard_normal(90), [-0.5, 0.5][: n_classes - 1])
    perm = np.argsort(rng.random((5, 90)), axis=1)
    blk = standardise_block(X)
    scaler = StandardScaler().fit(X)
    np.testing.assert_allclose(blk.offset, scaler.mean_, rtol=1e-13)
    np.testing.assert_allclose(blk.scale, scaler.scale_, rtol=1e-12)
    fit = fit_logistic_batch([blk], y[perm], C, tol=1e-10)  # ends by tol or ftol
    loose = fit_logistic_batch([blk], y[perm], C, tol=1e-6)  # ends by tol
    assert fit.converged.all() and loose.converged.all()
    Z = scaler.transform(X)
    for b in range(5):
        ref = sklearn_fit(Z, y[perm[b]], C)
        bound = assert_same_optimum(
            Z, y[perm[b]], np.ones(90), C, fit.coef[b], fit.intercept[b], ref, fit.classes
        )
        g = objective_gradient(
            Z, y[perm[b]], np.ones(90), loose.coef[b], loose.intercept[b], C, fit.classes
        )
        assert np.abs(g).max() <= 1e-6  # the stopping rule, checked by an independent formula
        test = DesignBlock(X, None, blk.offset, blk.scale)
        got = fit.predict([test])[b]
        # two solvers: the labels agree wherever the decision is farther from a tie than the
        # parameters' distance can move it. A decision (|d|, or the gap of the two largest
        # logits) is linear in the parameters through (z, 1): it moves by at most
        # ||(z, 1)|| x 2 x bound (two logits)
        d = ref.decision_function(Z)
        top2 = np.sort(d, axis=1)[:, -2:] if d.ndim == 2 else None
        margin = np.abs(d) if top2 is None else top2[:, 1] - top2[:, 0]
        radius = 2 * bound * np.linalg.norm(np.column_stack([Z, np.ones(90)]), axis=1)
        clear = margin > radius
        assert clear.mean() > 0.9  # the comparison covers nearly every row
        np.testing.assert_array_equal(got[clear], ref.predict(Z)[clear])


@pytest.mark.parametrize("n_classes", [2, 3])
def test_logistic_batch_wide_design_low_rank_basis_equals_sklearn(n_classes):
    """Fewer rows than columns (the density probe's shape): the preconditioner is the
    penalty's identity plus a rank <= n term; the optimum is still scikit-learn's."""
    rng = np.random.default_rng(10 + n_classes)
    n, d = 36, 150
    X = rng.standard_normal((n, 6)) @ rng.standard_normal((6, d)) + 0.1 * rng.standard_normal(
        (n, d)
    )
    y = np.arange(n) % n_classes
    blk = standardise_block(X)
    basis = block_basis(blk, 0.25 if n_classes == 2 else 1.0 / n_classes, 1.0 / n)
    assert basis.dense is None and basis.vecs.shape[1] <= n  # the low-rank form is used
    perm = np.argsort(rng.random((3, n)), axis=1)
    fit = fit_logistic_batch([blk], y[perm], 1.0, tol=1e-10)
    assert fit.converged.all()
    Z = StandardScaler().fit_transform(X)
    for b in range(3):
        ref = sklearn_fit(Z, y[perm[b]], 1.0)
        assert_same_optimum(
            Z, y[perm[b]], np.ones(n), 1.0, fit.coef[b], fit.intercept[b], ref, fit.classes
        )


def test_logistic_batch_separable_converges_by_the_l2_term():
    X, y = separable_three_class(seed=2)
    y2 = (y > 0).astype(int)
    for labels, k in ((y, 3), (y2, 2)):
        fit = fit_logistic_batch([standardise_block(X)], labels, 100.0, tol=1e-8)
        assert fit.converged.all() and 0 < fit.n_iter[0] < 12800  # iterations are recorded
        n = len(labels)
        # objective at the optimum <= at zero (log K): ||coef||^2 <= 2 C n log K
        assert np.sum(fit.coef**2) <= 2 * 100.0 * n * np.log(k)
        Z = StandardScaler().fit_transform(X)
        ref = sklearn_fit(Z, labels, 100.0)
        assert_same_optimum(
            Z, labels, np.ones(n), 100.0, fit.coef[0], fit.intercept[0], ref, fit.classes
        )
        assert accuracy(labels, fit.predict([DesignBlock(Z)])[0]) == 1.0


def test_logistic_batch_weights_equal_duplicated_rows_and_own_scaler():
    rng = np.random.default_rng(5)
    X = rng.standard_normal((60, 5)) * [1.0, 3.0, 0.2, 10.0, 1.0] + [0.0, 100.0, -3.0, 0.0, 7.0]
    y = np.digitize(X[:, 0] + 0.3 * X[:, 2] + 0.7 * rng.standard_normal(60), [-0.4, 0.6])
    idx = rng.integers(0, 60, (4, 60))
    counts = np.stack([np.bincount(i, minlength=60) for i in idx]).astype(float)
    blk = standardise_block(X, weights=counts)
    fit = fit_logistic_batch([blk], y, 1.0, sample_weight=counts, tol=1e-10)
    for b in range(4):
        scaler = StandardScaler().fit(X[idx[b]])
        np.testing.assert_allclose(blk.offset[b], scaler.mean_, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(blk.scale[b], scaler.scale_, rtol=1e-12)
        Z = scaler.transform(X[idx[b]])
        ref = sklearn_fit(Z, y[idx[b]], 1.0)
        assert_same_optimum(
            Z, y[idx[b]], np.ones(60), 1.0, fit.coef[b], fit.intercept[b], ref, fit.classes
        )


def test_logistic_batch_refuses_a_problem_missing_a_class():
    X = np.random.default_rng(0).standard_normal((20, 3))
    y = np.repeat([0, 1, 2], [8, 8, 4])
    w = np.ones((3, 20))
    w[1, y == 2] = 0.0  # resample 1 holds classes 0 and 1 only
    with pytest.raises(ValueError, match="problem 1 holds 2 of 3 classes; refit it alone"):
        fit_logistic_batch([standardise_block(X)], y, 1.0, sample_weight=w)
    with pytest.raises(ValueError, match="single class"):
        fit_logistic_batch([standardise_block(X)], np.zeros(20), 1.0)
