"""`probes.newton.newton_logistic_path` against scikit-learn's LogisticRegression, and the
logistic CV's loop that uses it (`logistic.fit_logistic` on two classes)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.linear_model import LogisticRegression
from test_probes import assert_cv_agrees, clear_best, cv_ambiguity

from tacgen_lib.probes import logistic
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.logistic import fit_logistic
from tacgen_lib.probes.newton import NewtonFit, newton_logistic_path


def binary_problem(seed: int, n: int, p: int, noise: float):
    """A standardised design whose two classes depend on a few columns plus noise."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, p)) * (2.0 / np.sqrt(1.0 + np.arange(p)))
    X = (X - X.mean(0)) / X.std(0)
    score = X[:, :3] @ np.array([1.0, -0.7, 0.4]) + noise * rng.standard_normal(n)
    return X, score > np.median(score)


def reference(X, positive, C):
    """scikit-learn's lbfgs run far past the probes' tolerance: the float64 minimiser."""
    return LogisticRegression(C=C, solver="lbfgs", max_iter=100_000, tol=1e-12).fit(X, positive)


@pytest.mark.parametrize(
    ("n", "p", "noise", "C_path"),
    [
        (40, 200, 1.0, [1e-4, 0.01, 0.1, 1.0, 10.0]),  # fewer rows than columns: Woodbury
        (300, 30, 1.0, [1e-4, 0.01, 0.1, 1.0, 10.0]),  # more rows than columns: p x p
        (60, 60, 0.05, [1.0, 100.0, 1e4]),  # nearly separable, weak penalties: steep steps
        (200, 8, 0.0, [1e4]),  # separable: only the penalty bounds the coefficients
    ],
)
def test_path_equals_scikit_learns_minimiser(n, p, noise, C_path):
    """At the probes' tolerance every fit meets lbfgs's stopping rule (each component of the
    mean objective's gradient within tol, computed here independently); at a tight one the
    path is the float64 minimiser scikit-learn reaches."""
    X, positive = binary_problem(n + p, n, p, noise)
    path = newton_logistic_path(X, positive, C_path, tol=1e-6)
    assert [fit.C for fit in path] == [float(c) for c in C_path]
    for fit in path:
        assert fit.converged and fit.n_iter < 50
        assert np.abs(mean_gradient(X, positive, fit)).max() <= 1e-6
    for fit in newton_logistic_path(X, positive, C_path, tol=1e-11):
        ref = reference(X, positive, fit.C)
        at_ref = NewtonFit(fit.C, ref.coef_[0], float(ref.intercept_[0]), 0, True)
        # scikit-learn stops on its relative-decrease rule first: the path ends nearer the
        # minimiser than it does, and within its distance of its answer
        g_path = np.abs(mean_gradient(X, positive, fit)).max()
        assert g_path <= max(np.abs(mean_gradient(X, positive, at_ref)).max(), 1e-11)
        d_ref = ref.decision_function(X)
        scale = max(1.0, float(np.abs(d_ref).max()))
        np.testing.assert_allclose(fit.decision(X), d_ref, atol=1e-5 * scale)


def mean_gradient(X, positive, fit):
    """The gradient of scikit-learn's objective (mean loss + ||coef||^2 / (2 C n)) at a fit."""
    n = X.shape[0]
    r = 1.0 / (1.0 + np.exp(-fit.decision(X))) - positive
    return np.append(X.T @ r / n + fit.coef / (fit.C * n), r.mean())


def test_a_path_gives_each_C_what_a_fit_from_zero_gives():
    """Starting each C from the previous one changes the iterates, not the minimiser."""
    X, positive = binary_problem(3, 50, 120, 0.5)
    path = newton_logistic_path(X, positive, [0.01, 1.0, 100.0], tol=1e-11)
    for fit in path:
        alone = newton_logistic_path(X, positive, [fit.C], tol=1e-11)[0]
        np.testing.assert_allclose(fit.decision(X), alone.decision(X), atol=1e-5)
    assert path[-1].n_iter <= newton_logistic_path(X, positive, [100.0], tol=1e-11)[0].n_iter


def test_an_exhausted_step_budget_is_reported_unconverged():
    X, positive = binary_problem(5, 80, 40, 0.3)
    (fit,) = newton_logistic_path(X, positive, [100.0], tol=1e-10, max_steps=1)
    assert not fit.converged and fit.n_iter == 1


def test_bad_inputs_are_refused():
    X, positive = binary_problem(1, 20, 5, 1.0)
    with pytest.raises(ValueError, match="do not match"):
        newton_logistic_path(X, positive[:-1], [1.0], tol=1e-6)
    with pytest.raises(ValueError, match="C must be > 0"):
        newton_logistic_path(X, positive, [1.0, 0.0], tol=1e-6)


@pytest.mark.parametrize(("n", "p"), [(40, 120), (120, 300)])
def test_the_cv_loop_gives_scikit_learns_scores_on_the_regimes_shapes(n, p):
    """The regime's probes: two classes, folds with fewer rows than columns (`cv_batches`
    False, so the loop runs its Newton paths). Its held-out scores are scikit-learn's fold fits'
    up to rows within the solvers' agreement radius of 0 (`cv_ambiguity`), so its C is theirs
    where no such row can change the choice; its final fit is scikit-learn's at that C."""
    rng = np.random.default_rng(n)
    X = rng.standard_normal((n, p)) * rng.uniform(0.1, 30.0, p) + rng.uniform(-50, 50, p)
    signal = X[:, :3] @ np.array([1.0, -0.5, 0.25]) / X[:, :3].std(0).mean()
    labels = np.where(signal + rng.standard_normal(n) > np.median(signal), "hard", "soft")
    labels = labels.astype(object)
    grid = [1e-4, 0.01, 0.1, 1.0, 10.0]
    folds = make_folds(n, 5, 7, labels=labels)
    assert not logistic.cv_batches(X.shape, folds)
    probe = fit_logistic(X, labels, grid, seed=7, n_folds=5, repeats=1)
    scores, ambiguous, n_held_out = cv_ambiguity(X, labels, folds, grid, tol=1e-6)
    slack = assert_cv_agrees(probe.cv_scores, scores.mean(axis=0), ambiguous, n_held_out)
    assert probe.cv_converged
    if clear_best(scores.mean(axis=0), slack):
        assert probe.C == grid[int(np.argmax(scores.mean(axis=0)))]
    final = logistic.fit_logistic_once(X, labels, probe.C, 12800, 12800, 1e-6)
    np.testing.assert_array_equal(probe.predict(X), final.model.predict(X))
