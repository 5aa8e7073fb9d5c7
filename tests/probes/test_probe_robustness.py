"""Probe robustness: protocol variants against scikit-learn, nested subsets, the
within-scale split, and multiple-comparison adjustments against SciPy / float64 references."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from probe_worlds import probe_settings
from scipy import stats
from sklearn.compose import TransformedTargetRegressor
from sklearn.linear_model import LogisticRegression, Ridge
from sklearn.model_selection import GridSearchCV
from sklearn.neural_network import MLPClassifier, MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tacgen_lib.probes import multiplicity
from tacgen_lib.probes.fit import fit_probe
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.mlp import FixedMLP, MLPGrid, fit_mlp_probe
from tacgen_lib.probes.objective import DesignBlock
from tacgen_lib.probes.protocol import run_family
from tacgen_lib.probes.protocol_variants import same_as_raw
from tacgen_lib.probes.refits import Refits
from tacgen_lib.probes.robustness import RobustnessSettings, training_size_sweep
from tacgen_lib.probes.rows import family_rows
from tacgen_lib.probes.scaling import FixedStandardisedRidge, fit_standardised_ridge
from tacgen_lib.probes.settings import ProbeSettings
from tacgen_lib.probes.subsets import nested_subsets, within_scale_split

LAMBDAS = (0.01, 0.1, 1.0, 10.0, 100.0)


def regression_data(n=80, m=30, p=12, seed=0):
    """Columns on wildly different scales (as raw pixel and ViT features are)."""
    rng = np.random.default_rng(seed)
    scales = np.logspace(-3, 3, p)
    X = rng.normal(size=(n + m, p)) * scales + rng.normal(size=p) * scales
    y = X[:, 0] / scales[0] + 0.5 * X[:, -1] / scales[-1] + rng.normal(0, 0.3, n + m)
    return X[:n], y[:n], X[n:], y[n:]


def class_data(n=90, m=30, p=8, seed=1):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n + m, p))
    y = np.where(X[:, 0] + X[:, 1] ** 2 > 0.8, "hard", "soft").astype(object)
    return X[:n], y[:n], X[n:], y[n:]


def settings(kind="ridge", protocol="raw", **kw):
    mlp = MLPGrid(widths=(8, 16), weight_decays=(0.01, 1.0), folds=3, max_iter=300)
    grid = dict(folds=4, bootstrap=200, seed=3, protocol=protocol, mlp=mlp)
    return probe_settings(kind, LAMBDAS, (0.1, 1.0, 10.0), **grid, **kw)


# --------------------------------------------------------------------------- standardised


def test_standardised_ridge_equals_sklearn_pipeline_gridsearch():
    X, y, Xt, _ = regression_data()
    folds = make_folds(len(y), 4, seed=3)
    cv = [(np.setdiff1d(np.arange(len(y)), f), f) for f in folds]
    ref = GridSearchCV(
        make_pipeline(StandardScaler(), Ridge()),
        {"ridge__alpha": list(LAMBDAS)},
        cv=cv,
        scoring="r2",
    ).fit(X, y)
    got = fit_standardised_ridge(X, y, LAMBDAS, n_folds=4, seed=3, repeats=1)
    assert got.lam == ref.best_params_["ridge__alpha"]
    np.testing.assert_allclose(got.cv_scores, ref.cv_results_["mean_test_score"], rtol=1e-9)
    np.testing.assert_allclose(got.predict(Xt), ref.predict(Xt), rtol=1e-8, atol=1e-10)
    # through the protocol entry point, with the raw probe differing on these scales
    fitted = fit_probe(X, y, Xt, settings(protocol="standardised"))
    np.testing.assert_allclose(fitted.pred_test, ref.predict(Xt), rtol=1e-8, atol=1e-10)
    raw = fit_probe(X, y, Xt, settings())
    assert not np.allclose(raw.pred_test, fitted.pred_test)


def test_standardisation_is_fitted_on_training_rows_only():
    X, y, Xt, _ = regression_data()
    probe = fit_standardised_ridge(X, y, LAMBDAS, n_folds=4, seed=3, repeats=1)
    np.testing.assert_allclose(probe.scaler.mean_, X.mean(axis=0))
    np.testing.assert_allclose(probe.scaler.scale_, X.std(axis=0))
    # Test rows cannot move it: predictions of the same test rows are the same whatever
    # other (wild, 1e6) test rows are scored beside them. The 30 rows inside a batch of 35 are
    # another product shape (BLAS may round differently): float64 unit roundoff 1.1e-16, two
    # products of <= 12-term sums (p = 12 features, <= 12 directions) of standardised O(10)
    # terms: ~24 x 1.1e-16 x 10 ~ 3e-14 -> rtol = atol = 1e-12; a scaler that saw the wild
    # rows would move them by orders of magnitude more
    wild = np.vstack([Xt, 1e6 * np.ones((5, X.shape[1]))])
    a = fit_probe(X, y, Xt, settings(protocol="standardised")).pred_test
    b = fit_probe(X, y, wild, settings(protocol="standardised")).pred_test[: len(Xt)]
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    # (each CV fold's scaler sees its fold-training rows only: the GridSearchCV-of-a-pipeline
    # equality above, which refits the scaler per fold, proves it)


def test_fixed_standardised_ridge_equals_pipeline_and_batches_targets():
    X, y, Xt, _ = regression_data()
    ref = make_pipeline(StandardScaler(), Ridge(alpha=3.0)).fit(X, y).predict(Xt)
    fixed = FixedStandardisedRidge(3.0)
    np.testing.assert_allclose(fixed.fit_predict(X, y, Xt), ref, rtol=1e-8, atol=1e-10)
    Y = np.stack([y, y[::-1], 2 * y])
    refits = Refits((DesignBlock(X),), (DesignBlock(Xt),), Y)
    got = fixed.refit_many(refits)
    assert got.solver == {"multi_target": 3}
    loop = fixed.refit_many(refits, batched=False).pred
    np.testing.assert_allclose(got.pred, loop, rtol=1e-8, atol=1e-10)


def test_standardised_logistic_is_raw():
    X, y, Xt, _ = class_data()
    raw = fit_probe(X, y, Xt, settings("logistic"))
    std = fit_probe(X, y, Xt, settings("logistic", "standardised"))
    np.testing.assert_array_equal(raw.pred_test, std.pred_test)
    assert same_as_raw("standardised", "logistic") and not same_as_raw("standardised", "ridge")
    ref = make_pipeline(StandardScaler(), LogisticRegression(C=raw.reg, tol=1e-6, max_iter=5000))
    ref.fit(X, y)
    # scikit-learn's lbfgs and the probe's (`probes.lbfgs`) are two computations of the same
    # iterates, whose decisions agree within 1e-5 (tests/probes/test_lbfgs.py): the labels
    # are compared exactly where no test row lies within 1e-4 of the boundary
    assert np.abs(ref.decision_function(Xt)).min() > 1e-4
    np.testing.assert_array_equal(raw.pred_test, ref.predict(Xt))


# --------------------------------------------------------------------------- mlp2


def test_mlp_regressor_equals_sklearn_gridsearch_same_seed():
    X, y, Xt, _ = regression_data(n=60, m=20, p=6)
    grid = MLPGrid(widths=(8, 16), weight_decays=(0.01, 1.0), folds=3, max_iter=100)
    folds = make_folds(len(y), 3, seed=5)
    cv = [(np.setdiff1d(np.arange(len(y)), f), f) for f in folds]
    est = TransformedTargetRegressor(
        regressor=make_pipeline(
            StandardScaler(), MLPRegressor(solver="lbfgs", max_iter=100, random_state=5)
        ),
        transformer=StandardScaler(),
    )
    params = {
        "regressor__mlpregressor__alpha": [0.01, 1.0],
        "regressor__mlpregressor__hidden_layer_sizes": [(8,), (16,)],
    }
    with _quiet():
        ref = GridSearchCV(est, params, cv=cv, scoring="r2").fit(X, y)
    got = fit_mlp_probe(X, y, "ridge", grid, seed=5)
    assert (got.weight_decay, (got.width,)) == (
        ref.best_params_["regressor__mlpregressor__alpha"],
        ref.best_params_["regressor__mlpregressor__hidden_layer_sizes"],
    )
    np.testing.assert_allclose(got.cv_scores, ref.cv_results_["mean_test_score"], rtol=1e-9)
    np.testing.assert_allclose(got.predict(Xt), ref.predict(Xt), rtol=1e-9, atol=1e-12)
    fixed = FixedMLP("ridge", got.width, got.weight_decay, 5, 100)
    np.testing.assert_allclose(fixed.fit_predict(X, y, Xt), ref.predict(Xt), rtol=1e-9)


def test_mlp_classifier_equals_sklearn_gridsearch_same_seed():
    X, y, Xt, _ = class_data()
    grid = MLPGrid(widths=(8,), weight_decays=(0.01, 1.0), folds=3, max_iter=100)
    folds = make_folds(len(y), 3, seed=2, labels=y)
    cv = [(np.setdiff1d(np.arange(len(y)), f), f) for f in folds]
    est = make_pipeline(
        StandardScaler(),
        MLPClassifier(hidden_layer_sizes=(8,), solver="lbfgs", max_iter=100, random_state=2),
    )
    with _quiet():
        ref = GridSearchCV(est, {"mlpclassifier__alpha": [0.01, 1.0]}, cv=cv).fit(X, y)
    got = fit_mlp_probe(X, y, "logistic", grid, seed=2)
    assert got.weight_decay == ref.best_params_["mlpclassifier__alpha"]
    np.testing.assert_allclose(got.cv_scores, ref.cv_results_["mean_test_score"])
    np.testing.assert_array_equal(got.predict(Xt), ref.predict(Xt))
    # seeded: the same seed gives the same probe, another seed another initialisation
    again = fit_mlp_probe(X, y, "logistic", grid, seed=2)
    np.testing.assert_array_equal(again.model[-1].coefs_[0], got.model[-1].coefs_[0])


class _quiet:
    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore")

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


# --------------------------------------------------------------------------- run_family


def _family(n=90, m=30, seed=0):
    rng = np.random.default_rng(seed)
    ids = np.array([f"s{i:03d}" for i in range(n + m)], dtype=object)
    v = rng.normal(size=(n + m, 5))
    t = rng.normal(size=(n + m, 6))
    y = v[:, 0] + 2 * t[:, 0] + rng.normal(0, 0.2, n + m)
    rows = family_rows(
        pd.DataFrame({"sample_id": ids, "corpus": "c", "y": y}),
        pd.DataFrame({"sample_id": ids, "split": ["train"] * n + ["test"] * m}),
        corpus="c",
        target="y",
        kind="ridge",
    )
    return rows, (v[:n], v[n:]), {"clip128": (t[:n], t[n:])}


@pytest.mark.parametrize("protocol", ["raw", "standardised", "mlp2"])
def test_every_protocol_runs_the_family_code_with_a_protocol_column(protocol):
    rows, vision, tactile = _family()
    res = run_family(
        "fam",
        rows,
        vision=vision,
        tactile=tactile,
        aligned={},
        fusions=["concat"],
        heads_variant="clip128",
        settings=settings(protocol=protocol),
        headline_only=protocol != "raw",
        controls=protocol == "raw",
    )
    main = res.rows.loc[res.rows["control"] == "none"].iloc[0]
    assert (res.rows["protocol"] == protocol).all()
    assert main["delta"] > 0.3 and main["ci_low"] > 0
    assert main["row_id"].endswith("|none") and (protocol == "raw") == ("p~" not in main["row_id"])
    if protocol == "mlp2":
        assert "width" in main["notes"] and main["reg_name"] == "weight_decay"
    if protocol != "raw":
        assert main["controls"] == "not run" and len(res.rows) == 1


# --------------------------------------------------------------------------- subsets


def test_nested_subsets_are_nested_stratified_and_seeded():
    labels = np.array(["a"] * 60 + ["b"] * 30 + ["c"] * 10, dtype=object)
    for seed in (0, 1, 2):
        subs = nested_subsets(100, [5, 10, 20, 50, 100, "all"], seed, labels=labels)
        assert 100 not in subs and list(subs) == [5, 10, 20, 50, "all"]
        sizes = [5, 10, 20, 50]
        for a, b in zip(sizes, sizes[1:], strict=False):
            assert set(subs[a]) < set(subs[b])
        assert set(subs[50]) < set(subs["all"]) and len(subs["all"]) == 100
        counts = pd.Series(labels[subs[20]]).value_counts()
        assert (counts["a"], counts["b"], counts["c"]) == (12, 6, 2)
        assert set(labels[subs[5]]) == {"a", "b", "c"}
    plain = nested_subsets(100, [10, 50], 7)
    assert set(plain[10]) < set(plain[50])
    assert not np.array_equal(nested_subsets(100, [10], 8)[10], plain[10])


def test_training_size_sweep_points_use_nested_training_rows_and_the_full_test():
    rows, vision, tactile = _family(n=80)
    out = training_size_sweep(
        "fam",
        rows,
        vision=vision,
        tactile=tactile["clip128"],
        settings=settings(),
        sizes=[10, 40, "all"],
        seeds=[0, 1],
    )
    assert list(out["n_train"]) == [10, 40, 80, 10, 40, 80]
    assert (out["n_test"] == rows.n_test).all() and out["row_id"].is_unique
    assert out.loc[out["n_requested"] == "all", "ci_low"].gt(0).all()


def test_within_scale_split_uses_training_rows_only_stratified_by_scale():
    rng = np.random.default_rng(0)
    n = 90
    ids = np.array([f"s{i:03d}" for i in range(n)], dtype=object)
    scale = np.repeat([0.15, 0.2, 0.25], 30)
    manifest = pd.DataFrame(
        {
            "sample_id": ids,
            "corpus": "c",
            "scale": scale,
            "shape": "box",
            "mass": rng.uniform(1, 2, n),
        }
    )
    splits = pd.DataFrame({"sample_id": ids, "split": np.where(scale == 0.25, "test", "train")})
    rows = family_rows(
        manifest, splits, corpus="c", target="mass", kind="ridge", within_scale=(0.33, 4)
    )
    used = set(rows.train_ids) | set(rows.test_ids)
    assert not used & set(ids[scale == 0.25])  # the held-out scale is never touched
    assert len(used) == 60 and not set(rows.train_ids) & set(rows.test_ids)
    test_scales = manifest.set_index("sample_id").loc[list(rows.test_ids), "scale"]
    assert test_scales.value_counts().to_dict() == {0.15: 10, 0.2: 10}
    tr, te = within_scale_split(np.array([1, 1, 2, 2, 2]), 0.5, 0)
    assert sorted([*tr, *te]) == [0, 1, 2, 3, 4] and len(te) == 3  # 1 of 2, round(1.5) of 3


def test_robustness_settings_from_every_config_and_jobs():
    from snakemake_run import validated

    for overlay in (None, "test.yaml", "paper.yaml"):
        cfg = validated(overlay)["probes"]
        rs = RobustnessSettings.from_config(cfg["robustness"], cfg["families"])
        jobs = rs.jobs(cfg["families"])
        assert len(set(jobs)) == len(jobs)
        assert ("hardness", "standardised") not in jobs  # logistic: standardised is raw
        assert {("force_null", "standardised"), ("hardness", "mlp2")} <= set(jobs)
        ps = ProbeSettings.from_config(cfg, "ridge", 42, protocol="mlp2")
        assert ps.mlp.widths == tuple(cfg["robustness"]["mlp"]["widths"])
    with pytest.raises(ValueError, match="not in probes.families"):
        RobustnessSettings.from_config({**cfg["robustness"], "families": ["nope"]}, cfg["families"])
    with pytest.raises(ValueError, match="probes.robustness.protocols"):
        RobustnessSettings.tiny(protocols=("raw", "quantum"))
    assert dataclasses.replace(RobustnessSettings.tiny(), controls=True).run_controls("mlp2")


# --------------------------------------------------------------------------- multiplicity


def holm_reference(p):
    """Holm in plain float64 loops: step down over sorted p, running max, cap 1."""
    p = [float(x) for x in p]
    m = len(p)
    order = sorted(range(m), key=lambda i: (p[i], i))
    out = [0.0] * m
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, (m - rank) * p[i])
        out[i] = min(1.0, running)
    return out


def test_holm_and_bh_equal_their_references():
    rng = np.random.default_rng(0)
    for p in (
        rng.uniform(size=50),
        rng.uniform(0, 0.05, 20),
        np.array([0.01, 0.01, 0.5, 1.0]),
        np.array([1e-300, 0.02, 0.03]),
        np.array([0.3]),
    ):
        np.testing.assert_allclose(multiplicity.holm(p), holm_reference(p), rtol=1e-15)
        np.testing.assert_allclose(
            multiplicity.benjamini_hochberg(p), stats.false_discovery_control(p, method="bh")
        )
    with pytest.raises(ValueError):
        multiplicity.holm(np.array([0.1, np.nan]))


def test_bootstrap_p_counts_resamples_at_or_below_zero():
    # 5000 resamples, 4990 above 0: 10 at or below -> (1 + 10) / 5001
    p = multiplicity.bootstrap_p(np.array([0.998, 1.0, 0.0]), np.array([5000, 5000, 5000]))
    np.testing.assert_allclose(p, [11 / 5001, 1 / 5001, 1.0])


def test_holm_over_all_comparisons_is_bounded_by_the_bootstrap_resolution():
    # the smallest bootstrap p is 1 / (B + 1): Holm over m such p-values gives m / (B + 1)
    b = 5000
    for m, can in ((125, True), (126, False), (148, False)):
        assert multiplicity.holm_can_reject(m, b) is can
        smallest = multiplicity.holm(np.full(m, 1 / (b + 1))).min()
        assert bool(smallest < multiplicity.ALPHA_ONE_SIDED) is can


def test_adjusted_criterion_uses_holm_within_the_family():
    # 130 comparisons, all at the smallest bootstrap p: over all of them Holm rejects nothing,
    # within a family of 10 it rejects every one
    rows = [
        {
            "row_id": f"r{i}",
            "family": f"f{i // 10}",
            "control": "none",
            "status": "ok",
            "protocol": "raw",
            "null_corpus": False,
            "delta": 0.3,
            "ci_low": 0.1,
            "ci_high": 0.5,
            "p_gt0": 1.0,
            "n_resamples": 5000,
            "delta_ctrl": 0.0,
            "criterion_met": True,
        }
        for i in range(130)
    ]
    out = multiplicity.adjust(pd.DataFrame(rows))
    assert (out["p_holm"] >= multiplicity.ALPHA_ONE_SIDED).all()
    assert (out["p_holm_family"] < multiplicity.ALPHA_ONE_SIDED).all()
    assert out["criterion_adjusted"].all()


def test_adjust_and_counts_per_family_and_overall():
    rows = []
    for fam, null, deltas in (("a", False, [0.5, 0.4, 0.01]), ("a_null", True, [0.0, -0.1])):
        for i, d in enumerate(deltas):
            rows.append(
                {
                    "row_id": f"{fam}{i}",
                    "family": fam,
                    "control": "none",
                    "status": "ok",
                    "protocol": "raw",
                    "null_corpus": null,
                    "delta": d,
                    "ci_low": d - 0.05,
                    "ci_high": d + 0.05,
                    "p_gt0": 1.0 if d > 0.1 else 0.5,
                    "n_resamples": 1000,
                    "delta_ctrl": 0.0,
                    "criterion_met": d > 0.1,
                }
            )
    out = multiplicity.adjust(pd.DataFrame(rows))
    np.testing.assert_allclose(out["p_holm"], holm_reference(out["p_boot"]))
    fam_a = out["family"] == "a"
    np.testing.assert_allclose(
        out.loc[fam_a, "p_holm_family"], holm_reference(out.loc[fam_a, "p_boot"])
    )
    assert list(out["criterion_adjusted"]) == [True, True, False, False, False]
    counts = multiplicity.ci_counts(out).set_index("family")
    assert counts.loc["all", "comparisons"] == 5 and counts.loc["a", "ci_excludes_0"] == 2
    assert counts.loc["a_null", "ci_below_0"] == 1
    assert counts.loc["null corpora", "expected_by_chance"] == pytest.approx(0.1)
