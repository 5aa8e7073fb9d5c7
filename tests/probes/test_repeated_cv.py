"""Repeated K-fold CV (`make_folds(..., repeats=R)`, `ProbeSettings.cv_repeats`): R partitions
one after another, the first the single draw's; a CV score is the mean over every fold of every
draw, checked against scikit-learn's GridSearchCV on the same folds and against the mean of the
draws' own CVs; one draw is today's probe bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sklearn.linear_model import Ridge
from sklearn.model_selection import GridSearchCV

from tacgen_lib.probes.fit import fit_probe
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.logistic import fit_logistic
from tacgen_lib.probes.ridge_cv import select_lambda_cv
from tacgen_lib.probes.settings import ProbeSettings


@pytest.mark.parametrize("stratified", [False, True])
def test_repeats_are_partitions_and_the_first_is_the_single_draw(stratified):
    labels = np.arange(47) % 3 if stratified else None
    one = make_folds(47, 4, 9, labels=labels)
    many = make_folds(47, 4, 9, labels=labels, repeats=3)
    assert len(many) == 12
    for a, b in zip(one, many[:4], strict=True):
        np.testing.assert_array_equal(a, b)
    for r in range(3):
        draw = many[4 * r : 4 * r + 4]
        np.testing.assert_array_equal(np.sort(np.concatenate(draw)), np.arange(47))
        if stratified:  # every fold of every draw holds every class
            assert all(set(labels[f]) == {0, 1, 2} for f in draw)
    # the draws differ from each other and from another seed's first draw
    assert not all(np.array_equal(a, b) for a, b in zip(many[:4], many[4:8], strict=True))
    other = make_folds(47, 4, 10, labels=labels)
    assert not all(np.array_equal(a, b) for a, b in zip(many[4:8], other, strict=True))
    with pytest.raises(ValueError, match="repeats >= 1, got 0"):
        make_folds(47, 4, 9, repeats=0)


def test_repeated_ridge_cv_is_gridsearchcv_on_all_folds_and_the_mean_of_the_draws():
    rng = np.random.default_rng(2)
    X = rng.standard_normal((40, 60))  # fewer rows than features: the Gram (dual) path
    y = X[:, :3].sum(axis=1) + rng.standard_normal(40)
    lambdas = [0.1, 1.0, 10.0, 100.0]
    sel = select_lambda_cv(X, y, lambdas, n_folds=4, seed=5, repeats=3)
    folds = make_folds(40, 4, 5, repeats=3)
    cv = [(np.setdiff1d(np.arange(40), f), f) for f in folds]
    gs = GridSearchCV(Ridge(), {"alpha": lambdas}, cv=cv, scoring="r2").fit(X, y)
    np.testing.assert_allclose(sel.cv_scores, gs.cv_results_["mean_test_score"], rtol=1e-9)
    per_draw = [
        select_lambda_cv(
            X, y, lambdas, folds=folds[4 * r : 4 * r + 4], repeats=1, seed=0, n_folds=5
        ).cv_scores
        for r in range(3)
    ]
    np.testing.assert_allclose(sel.cv_scores, np.mean(per_draw, axis=0), rtol=1e-12)
    assert sel.lam == lambdas[int(np.argmax(gs.cv_results_["mean_test_score"]))]


def test_repeated_logistic_cv_is_the_mean_of_its_draws():
    rng = np.random.default_rng(4)
    X = rng.standard_normal((90, 5))
    y = np.where(X[:, 0] + 0.8 * rng.standard_normal(90) > 0, "hard", "soft")
    grid = [0.01, 0.1, 1.0]
    probe = fit_logistic(X, y, grid, seed=3, n_folds=3, repeats=4)
    folds = make_folds(90, 3, 3, labels=y, repeats=4)
    # the one-draw CV on each draw's folds, through the same code: its scores are the means
    # over that draw's 3 folds, and the repeated score the mean over all 12
    seeds = []
    for r in range(4):
        draw = folds[3 * r : 3 * r + 3]
        scores = []
        for c in grid:
            acc = []
            for ho in draw:
                tr = np.setdiff1d(np.arange(90), ho)
                fit = fit_logistic(X[tr], y[tr], [c], seed=0, n_folds=2, repeats=1)
                acc.append(np.mean(fit.predict(X[ho]) == y[ho]))
            scores.append(np.mean(acc))
        seeds.append(scores)
    # held-out labels of rows whose decision is within the solvers' tolerance of 0 may differ
    # between the CV's batched solve and these one-at-a-time fits: one row of 30 at most
    np.testing.assert_allclose(probe.cv_scores, np.mean(seeds, axis=0), atol=1 / 30 / 4 + 1e-12)


@pytest.mark.parametrize("kind", ["ridge", "logistic"])
def test_one_draw_is_the_probe_of_before_and_more_draws_pass_through_fit_probe(kind):
    rng = np.random.default_rng(7)
    X = rng.standard_normal((60, 8))
    signal = X[:, 0] + 0.5 * rng.standard_normal(60)
    y = signal if kind == "ridge" else np.where(signal > 0, "a", "b")
    cfg = {"lambdas": [0.1, 1, 10], "C": [0.1, 1, 10], "folds": 3, "bootstrap": 100}
    cfg |= dict.fromkeys(("train_resamples", "permutations", "label_permutations"), 0)
    ps = ProbeSettings.from_config(cfg | {"random_draws": 0}, kind, 0)
    assert ps.cv_repeats == 1
    one = fit_probe(X[:45], y[:45], X[45:], ps)
    if kind == "ridge":
        direct = select_lambda_cv(X[:45], y[:45], cfg["lambdas"], n_folds=3, seed=0, repeats=1)
    else:
        direct = fit_logistic(X[:45], y[:45], cfg["C"], 0, n_folds=3, repeats=1)
    np.testing.assert_array_equal(one.cv_scores, direct.cv_scores)
    five = fit_probe(X[:45], y[:45], X[45:], dataclasses.replace(ps, cv_repeats=5))
    if kind == "ridge":
        want = select_lambda_cv(X[:45], y[:45], cfg["lambdas"], n_folds=3, seed=0, repeats=5)
    else:
        want = fit_logistic(X[:45], y[:45], cfg["C"], 0, n_folds=3, repeats=5)
    np.testing.assert_array_equal(five.cv_scores, want.cv_scores)
    with pytest.raises(ValueError, match="probes.cv_repeats must be an integer >= 1"):
        dataclasses.replace(ps, cv_repeats=0)
