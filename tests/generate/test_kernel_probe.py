"""The exact RBF-kernel probe (tacgen_lib.generate.small_probes.fit_kernel_probe), the
visibility check's nonlinear probe and the regime's V ceiling: the same choice and predictions
as scikit-learn's grid search over the same folds, a factor only a nonlinear probe reads, one
that the rank of the Nystroem map caps, and the labels CV cannot handle."""

from __future__ import annotations

import numpy as np
import pytest
from generate_worlds import small_probes
from scipy.spatial.distance import pdist
from sklearn.kernel_ridge import KernelRidge
from sklearn.model_selection import GridSearchCV
from sklearn.svm import SVC

from tacgen_lib.generate.baselines import median_sq_distance, standardise
from tacgen_lib.generate.small_probes import (
    _cv_draw,
    fit_kernel_probe,
    fit_small_nonlinear,
    fit_small_probe,
)
from tacgen_lib.probes.folds import make_folds

GAMMAS, C = (0.5, 1.0, 2.0), (1.0, 10.0, 100.0)


def _ring(n: int = 240, seed: int = 0, d: int = 6):
    """Class = which of three rings (radius 1, 2, 3) a row's first two columns lie on: no
    linear probe can read it; the other columns are noise."""
    rng = np.random.default_rng(seed)
    y = rng.integers(3, size=n)
    angle = rng.uniform(0, 2 * np.pi, n)
    radius = (y + 1) + 0.15 * rng.normal(size=n)
    x = np.column_stack(
        [radius * np.cos(angle), radius * np.sin(angle), rng.normal(size=(n, d - 2))]
    )
    return x, y.astype(str)


def _reference(model, grid: dict, x_tr, y_tr, x_te, settings, labels):
    """scikit-learn's grid search over the probe's own folds, on the probe's standardised rows
    and median-heuristic gammas."""
    mu, sd = x_tr.mean(0), x_tr.std(0)
    sd = np.where(sd > 0, sd, 1.0)
    z_tr, z_te = (x_tr - mu) / sd, (x_te - mu) / sd
    med = float(np.median(pdist(z_tr[:500], "sqeuclidean")))
    folds = make_folds(len(y_tr), settings.folds, settings.seed, labels=labels)
    cv = [(np.setdiff1d(np.arange(len(y_tr)), ho), ho) for ho in folds]
    grid = {**grid, "gamma": [g / med for g in GAMMAS]}
    scoring = "accuracy" if labels is not None else "r2"
    search = GridSearchCV(model, grid, cv=cv, scoring=scoring).fit(z_tr, y_tr)
    return search, search.predict(z_te), med


def test_the_svm_is_scikit_learns_grid_search_on_the_same_folds():
    x, y = _ring()
    settings = small_probes("logistic", [1.0], list(C), seed=3)
    got = fit_kernel_probe(x[:180], y[:180], x[180:], settings, gammas=GAMMAS, C=C)
    search, pred, med = _reference(
        SVC(), {"C": list(C)}, x[:180], y[:180], x[180:], settings, y[:180]
    )
    assert got.source == "cv"
    assert got.reg == search.best_params_["C"]
    assert got.gamma_multiple == pytest.approx(search.best_params_["gamma"] * med, rel=1e-12)
    assert list(got.pred) == list(pred)


def test_a_continuous_target_is_kernel_ridge_over_the_familys_lambdas():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(200, 4))
    y = np.sin(2 * x[:, 0]) + x[:, 1] ** 2 + 0.1 * rng.normal(size=200)
    lambdas = [0.01, 0.1, 1.0]
    settings = small_probes("ridge", lambdas, [1.0], seed=5)
    got = fit_kernel_probe(x[:150], y[:150], x[150:], settings, gammas=GAMMAS, C=C)
    search, pred, med = _reference(
        KernelRidge(kernel="rbf"), {"alpha": lambdas}, x[:150], y[:150], x[150:], settings, None
    )
    assert got.reg == search.best_params_["alpha"]
    assert got.gamma_multiple == pytest.approx(search.best_params_["gamma"] * med, rel=1e-12)
    np.testing.assert_allclose(got.pred.astype(float), pred, rtol=1e-9, atol=1e-9)


def test_it_reads_what_no_linear_probe_can_and_repeats_itself():
    x, y = _ring(seed=2, d=3)  # one noise column
    settings = small_probes("logistic", [1.0], [0.1, 1, 10], seed=0)
    kernel = fit_kernel_probe(x[:180], y[:180], x[180:], settings, gammas=GAMMAS, C=C)
    linear = fit_small_probe(x[:180], y[:180], x[180:], settings)
    acc = lambda fit: float(np.mean(fit.pred == y[180:]))  # noqa: E731
    assert acc(kernel) > 0.9
    assert acc(linear) < 0.6  # three classes: chance is a third
    again = fit_kernel_probe(x[:180], y[:180], x[180:], settings, gammas=GAMMAS, C=C)
    assert list(again.pred) == list(kernel.pred) and again.reg == kernel.reg


def test_it_is_not_capped_by_the_rank_of_a_nystroem_map():
    """Many small clusters in two dimensions: the nonlinear baseline's Nystroem map has as
    many components as V has columns (2 here), too few to separate 16 clusters; the exact
    kernel separates them."""
    rng = np.random.default_rng(4)
    centres = np.array([(i, j) for i in range(4) for j in range(4)], dtype=float) * 3.0
    k = rng.integers(16, size=640)
    y = np.where((k // 4 + k % 4) % 2 == 0, "a", "b").astype(object)  # neighbours differ
    x = centres[k] + 0.4 * rng.normal(size=(640, 2))
    settings = small_probes("logistic", [1.0], [0.1, 1, 10], seed=0)
    exact = fit_kernel_probe(x[:480], y[:480], x[480:], settings, gammas=(1.0, 4.0, 16.0), C=C)
    capped = fit_small_nonlinear(
        x[:480], y[:480], x[480:], settings, gammas=(1.0, 4.0, 16.0), n_components=2
    )
    assert np.mean(exact.pred == y[480:]) > 0.95
    assert np.mean(capped.pred == y[480:]) < 0.8


def test_labels_cv_cannot_split_fall_back_to_the_small_probe():
    x, _ = _ring(n=40)
    settings = small_probes("logistic", [1.0], [0.1, 1, 10], seed=0)
    one = np.array(["a"] * 40, dtype=object)
    got = fit_kernel_probe(x[:30], one[:30], x[30:], settings, gammas=GAMMAS, C=C)
    assert got.source == "single class: constant" and set(got.pred) == {"a"}
    lone = np.array(["a"] * 29 + ["b"], dtype=object)  # a class with one row: no stratified CV
    got = fit_kernel_probe(x[:30], lone, x[30:], settings, gammas=GAMMAS, C=C)
    ref = fit_small_probe(x[:30], lone, x[30:], settings)
    assert got.source == ref.source == "fixed C (a class with < 2 rows)"
    assert list(got.pred) == list(ref.pred)


def _smooth(n: int, seed: int):
    """A continuous target that only a nonlinear function of x carries."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 4))
    return x, np.sin(2 * x[:, 0]) + x[:, 1] ** 2 + 0.1 * rng.normal(size=n)


def _fit(x, y, n_train: int, settings, large=None):
    """The kernel probe on the first `n_train` rows, predicting the rest."""
    return fit_kernel_probe(
        x[:n_train], y[:n_train], x[n_train:], settings, gammas=GAMMAS, C=C, large=large
    )


def test_above_the_threshold_kernel_ridge_is_the_low_rank_kernels_ridge():
    """More train rows than the Nystroem threshold: ridge on the Nystroem features, which is kernel
    ridge with the low-rank kernel those features span (the same penalty means the same), so
    it equals scikit-learn's KernelRidge on that precomputed kernel, within float rounding."""
    from sklearn.kernel_approximation import Nystroem

    x, y = _smooth(300, 6)
    settings = small_probes("ridge", [0.01, 0.1, 1.0], [1.0], seed=2)
    got = _fit(x, y, 200, settings, large=(150, 60))
    exact = _fit(x, y, 200, settings)
    assert got.source == "cv, Nystroem rank 60" and exact.source == "cv"
    mu, sd = x[:200].mean(0), x[:200].std(0)
    z_tr, z_te = (x[:200] - mu) / sd, (x[200:] - mu) / sd
    med = float(np.median(pdist(z_tr, "sqeuclidean")))
    nys = Nystroem(
        kernel="rbf", gamma=got.gamma_multiple / med, n_components=60, random_state=2
    ).fit(z_tr)
    phi_tr, phi_te = nys.transform(z_tr), nys.transform(z_te)
    low_rank = KernelRidge(alpha=got.reg, kernel="precomputed").fit(phi_tr @ phi_tr.T, y[:200])
    np.testing.assert_allclose(
        got.pred.astype(float), low_rank.predict(phi_te @ phi_tr.T), rtol=1e-6, atol=1e-8
    )
    # at or below the threshold, and for a class label at any size, the exact kernel
    same = _fit(x, y, 200, settings, large=(200, 60))
    assert same.source == "cv" and same.reg == exact.reg
    np.testing.assert_allclose(same.pred.astype(float), exact.pred.astype(float), rtol=1e-9)


def test_a_large_svm_chooses_its_grid_on_a_draw_and_refits_on_every_row():
    """More train rows than `large`'s rows: the SVM stays exact, its (C, gamma) chosen as
    scikit-learn's grid search chooses them on a stratified draw of that many rows (the
    family's folds of the draw), then refitted on every train row."""
    x, y = _ring(n=240, seed=5)
    settings = small_probes("logistic", [1.0], list(C), seed=3)
    got = _fit(x, y, 180, settings, large=(120, 5))
    assert got.source == "cv on 120 of 180 rows"
    labels = y[:180].astype(str)
    drawn = _cv_draw(labels, 120, 3)
    assert len(set(drawn)) == 120 and set(labels[drawn]) == set(labels)
    z_tr, z_te = standardise(x[:180], x[180:])
    med = median_sq_distance(z_tr)
    folds = make_folds(120, settings.folds, settings.seed, labels=labels[drawn])
    cv = [(np.setdiff1d(np.arange(120), ho), ho) for ho in folds]
    grid = {"C": list(C), "gamma": [g / med for g in GAMMAS]}
    search = GridSearchCV(SVC(), grid, cv=cv, scoring="accuracy").fit(z_tr[drawn], labels[drawn])
    assert got.reg == search.best_params_["C"]
    assert got.gamma_multiple == pytest.approx(search.best_params_["gamma"] * med, rel=1e-12)
    refit = SVC(C=got.reg, gamma=got.gamma_multiple / med).fit(z_tr, labels).predict(z_te)
    assert list(got.pred) == list(refit)


def test_the_nystroem_ceiling_tracks_the_exact_one_where_both_fit():
    """The V ceiling's kernel ridge above regime.nystroem_above: at a rank a quarter of the train
    rows it scores within a few hundredths of R^2 of the exact kernel on the same rows, and
    well above the linear probe (a bound that the approximation does not pull down to the
    linear one)."""
    from tacgen_lib.probes.metrics import score

    x, y = _smooth(1200, 7)
    settings = small_probes("ridge", [0.01, 0.1, 1.0], [1.0], seed=0)
    exact = _fit(x, y, 900, settings)
    low = _fit(x, y, 900, settings, large=(512, 225))
    linear = fit_small_probe(x[:900], y[:900], x[900:], settings)
    r2 = lambda fit: score("r2", y[900:], fit.pred.astype(float))  # noqa: E731
    assert abs(r2(low) - r2(exact)) < 0.03
    assert r2(low) > r2(linear) + 0.3
