"""Bootstrap CIs, controls and the paper's criterion, against scipy / plain-loop references."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.stats
from sklearn.metrics import accuracy_score, r2_score

from tacgen_lib.probes.batched import concat_ridge_permuted
from tacgen_lib.probes.bootstrap import (
    fixed_test_bootstrap,
    percentile_interval,
    resample_indices,
)
from tacgen_lib.probes.controls import (
    PairedRows,
    label_permutation_control,
    paper_criterion,
    random_feature_control,
    tactile_permutation_control,
    train_resample_diagnostic,
)
from tacgen_lib.probes.fusion import fuse
from tacgen_lib.probes.logistic import FixedLogistic, fit_logistic_once
from tacgen_lib.probes.metrics import r2
from tacgen_lib.probes.objective import DesignBlock
from tacgen_lib.probes.refits import Refits, Refitted
from tacgen_lib.probes.ridge import FixedRidge


def make_preds(n=80, seed=0):
    rng = np.random.default_rng(seed)
    y = rng.standard_normal(n)
    return y, y + 0.9 * rng.standard_normal(n), y + 0.6 * rng.standard_normal(n)


def delta_loop(metric, y, pv, pvt, idx):
    """Plain-loop float64 reference: one resample at a time with scikit-learn's metrics."""
    f = r2_score if metric == "r2" else accuracy_score
    return np.array([f(y[i], pvt[i]) - f(y[i], pv[i]) for i in idx])


def test_bootstrap_equals_scipy_percentile_ci_on_identical_resamples():
    y, pv, pvt = make_preds()
    seen = []

    def delta_r2(i, axis=-1):  # statistic over resampled row indices, vectorised
        if i.ndim == 2:
            seen.append(i.copy())
        yi = y[i]
        ss_tot = np.sum((yi - yi.mean(axis=axis, keepdims=True)) ** 2, axis=axis)
        return (np.sum((yi - pv[i]) ** 2, axis=axis) - np.sum((yi - pvt[i]) ** 2, axis=axis)) / (
            ss_tot
        )

    ref = scipy.stats.bootstrap(
        (np.arange(y.size),),
        delta_r2,
        n_resamples=2000,
        vectorized=True,
        method="percentile",
        rng=np.random.default_rng(5),
    )
    got = fixed_test_bootstrap(y, pv, pvt, "r2", n_resamples=2000, seed=5)
    idx = resample_indices(y.size, 2000, seed=5)
    assert np.array_equal(np.concatenate(seen), idx)  # same Generator call -> same resamples
    assert got["ci_low"] == pytest.approx(ref.confidence_interval.low, rel=1e-12)
    assert got["ci_high"] == pytest.approx(ref.confidence_interval.high, rel=1e-12)


def test_percentile_interval_is_numpys_central_quantiles():
    values = np.random.default_rng(2).normal(size=1001)
    assert percentile_interval(values) == pytest.approx(np.quantile(values, [0.025, 0.975]))
    assert percentile_interval(values, confidence_level=0.5) == pytest.approx(
        np.quantile(values, [0.25, 0.75])
    )
    with pytest.raises(ValueError, match="confidence_level must be in"):
        percentile_interval(values, confidence_level=1.0)


@pytest.mark.parametrize("metric", ["r2", "accuracy"])
def test_bootstrap_equals_plain_loop_reference(metric):
    y, pv, pvt = make_preds(60, seed=1)
    if metric == "accuracy":
        y, pv, pvt = (np.digitize(a, [-0.5, 0.5]) for a in (y, pv, pvt))
    got = fixed_test_bootstrap(y, pv, pvt, metric, 500, seed=2, return_distribution=True)
    idx = resample_indices(y.size, 500, seed=2)
    ref = delta_loop(metric, y, pv, pvt, idx)
    np.testing.assert_allclose(got["deltas"], ref, rtol=1e-12, atol=1e-14)
    lo, hi = np.quantile(ref, [0.025, 0.975])
    assert got["ci_low"] == pytest.approx(lo, abs=1e-13)
    assert got["ci_high"] == pytest.approx(hi, abs=1e-13)
    assert got["p_gt0"] == np.mean(ref > 0)
    full = r2_score if metric == "r2" else accuracy_score
    assert got["delta"] == pytest.approx(full(y, pvt) - full(y, pv), abs=1e-14)


def test_stratified_resamples_keep_strata_and_match_loop():
    y, pv, pvt = make_preds(45, seed=3)
    strata = np.repeat(["cube-dense-s", "sphere-soft-m", "cyl-dense-l"], [20, 15, 10])
    idx = resample_indices(45, 300, seed=9, strata=strata)
    assert np.all(strata[idx] == strata[None, :])  # every column drawn from its own stratum
    got = fixed_test_bootstrap(y, pv, pvt, "r2", 300, 9, strata, return_distribution=True)
    np.testing.assert_allclose(got["deltas"], delta_loop("r2", y, pv, pvt, idx), rtol=1e-12)


def test_constant_target_resample_is_defined_and_finite():
    y = np.array([2.0, 2.0, 2.0, 5.0, 7.0])
    pv = np.array([2.0, 2.0, 2.0, 4.0, 8.0])  # exact on the constant rows
    pvt = np.array([2.5, 2.0, 1.0, 5.0, 7.0])
    idx = np.array([[0, 1, 2, 0, 1], [0, 0, 0, 0, 0], [1, 2, 3, 4, 0], [3, 3, 3, 3, 3]])
    got = fixed_test_bootstrap(y, pv, pvt, "r2", len(idx), 0, indices=idx, return_distribution=True)
    # Resamples 0 and 1 are constant (y = 2): V exact -> R2 := 1, V+T off on row 0 -> 0.
    # Resample 3 is constant (y = 5): V off -> 0, V+T exact -> 1. Resample 2 is ordinary.
    ref = [0.0 - 1.0, 0.0 - 1.0, r2(y[idx[2]], pvt[idx[2]]) - r2(y[idx[2]], pv[idx[2]]), 1.0]
    np.testing.assert_allclose(got["deltas"], ref, rtol=1e-12)
    assert got["n_constant_resamples"] == 3
    assert np.isfinite([got["ci_low"], got["ci_high"]]).all()
    assert r2_score(y[idx[2]], pvt[idx[2]]) == pytest.approx(r2(y[idx[2]], pvt[idx[2]]))


def test_single_class_resample_accuracy():
    y = np.array([0, 0, 1, 2])
    pv, pvt = np.array([0, 1, 1, 2]), np.array([0, 0, 2, 2])
    idx = np.array([[0, 1, 0, 1], [0, 1, 2, 3]])
    got = fixed_test_bootstrap(
        y, pv, pvt, "accuracy", len(idx), 0, indices=idx, return_distribution=True
    )
    np.testing.assert_allclose(got["deltas"], [1.0 - 0.5, 0.75 - 0.75])


def control_data(n_tr=70, n_te=40, dv=6, dt=9, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.standard_normal((n_tr + n_te, dv))
    t = rng.standard_normal((n_tr + n_te, dt))
    y = v[:, 0] + 1.5 * t[:, 0] + 0.3 * rng.standard_normal(n_tr + n_te)
    return v[:n_tr], t[:n_tr], y[:n_tr], v[n_tr:], t[n_tr:], y[n_tr:]


@pytest.mark.parametrize(
    "dims,solver", [((6, 9), "pcg"), ((40, 50), "pcg"), ((40, 50), "cholesky")]
)  # primal refit loop (p < n); batched dual kernel path (p >= n) by PCG or Cholesky
def test_tactile_permutation_fast_path_equals_refit_loop(dims, solver):
    v_tr, t_tr, y_tr, v_te, t_te, y_te = control_data(dv=dims[0], dt=dims[1])
    kw = dict(metric="r2", n_permutations=12, seed=4)
    rows = PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te)
    fast = tactile_permutation_control(rows, probe=FixedRidge(2.0, solver=solver), **kw)
    rng = np.random.default_rng(4)  # the documented draw: training permutations only
    p_tr = np.argsort(rng.random((12, 70)), axis=1, kind="stable")
    v_score = r2_score(y_te, FixedRidge(2.0).fit_predict(v_tr, y_tr, v_te))
    loop = []
    for a in p_tr:  # the paper's control: permuted training T, intact test T
        pred = FixedRidge(2.0).fit_predict(
            fuse("concat", v_tr, t_tr[a]), y_tr, fuse("concat", v_te, t_te)
        )
        loop.append(r2_score(y_te, pred) - v_score)
    np.testing.assert_allclose(fast["deltas"], loop, rtol=1e-9, atol=1e-11)
    real = (
        r2_score(
            y_te,
            FixedRidge(2.0).fit_predict(
                fuse("concat", v_tr, t_tr), y_tr, fuse("concat", v_te, t_te)
            ),
        )
        - v_score
    )
    assert fast["delta_ctrl"] < real  # T carries signal only when paired


class SpyProbe:
    """Wraps a fixed probe, records every (X_train, X_test) its refit loop is given."""

    def __init__(self, probe):
        self.probe, self.calls = probe, []

    def fit_predict(self, X_train, y_train, X_test):
        self.calls.append((X_train.copy(), X_test.copy()))
        return self.probe.fit_predict(X_train, y_train, X_test)

    def batches(self, refits):
        return False

    def refit_many(self, refits, *, batched=None):
        return Refitted(refits.loop(self.fit_predict), {"refits": refits.n_problems})


@pytest.mark.parametrize("fusion", ["concat", "mean"])
def test_tactile_permutation_keeps_test_tactile_intact(fusion):
    """The paper's control permutes the TRAINING T only: every refit sees the test rows'
    own fuse(V, T), and its training T is a permutation of the real one."""
    v_tr, t_tr, y_tr, v_te, t_te, y_te = control_data(dv=6, dt=6)
    spy = SpyProbe(FixedRidge(2.0))
    rows = PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te, fusion=fusion)
    tactile_permutation_control(
        rows, probe=spy, probe_v=FixedRidge(2.0), metric="r2", n_permutations=5, seed=3
    )
    assert len(spy.calls) == 5
    x_te = fuse(fusion, v_te, t_te)
    moved = 0
    for x_train, x_test in spy.calls:
        np.testing.assert_array_equal(x_test, x_te)  # the test block is untouched
        moved += not np.array_equal(x_train, fuse(fusion, v_tr, t_tr))
    assert moved == 5  # every training T was permuted


def test_tactile_permutation_batched_equals_loop_with_intact_test():
    """Kernel path (ridge) and batched solver (logistic) against the refit loop."""
    v_tr, t_tr, y_tr, v_te, t_te, y_te = control_data(dv=40, dt=50)
    rows = PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te)
    kw = dict(metric="r2", n_permutations=8, seed=2)
    fast = tactile_permutation_control(rows, probe=FixedRidge(2.0), **kw)
    assert "pcg_iterations" in fast["solver"]  # the batched kernel path ran
    loop = tactile_permutation_control(rows, probe=SpyProbe(FixedRidge(2.0)), **kw)
    np.testing.assert_allclose(fast["deltas"], loop["deltas"], rtol=1e-9, atol=1e-11)
    v_tr, t_tr, c_tr, v_te, t_te, c_te = class_data(n_classes=3)
    rows = PairedRows(v_tr, t_tr, c_tr, v_te, t_te, c_te)
    kw = dict(metric="accuracy", n_permutations=6, seed=5)
    fast = tactile_permutation_control(rows, probe=TIGHT, **kw)
    assert fast["solver"] == {"batched_logistic": 6}
    loop = tactile_permutation_control(rows, probe=SpyProbe(CHECKED_TIGHT), probe_v=TIGHT, **kw)
    np.testing.assert_array_equal(fast["vt_scores"], loop["vt_scores"])


def test_pcg_stragglers_fall_back_to_cholesky():
    v_tr, t_tr, y_tr, v_te, t_te, _ = control_data(dv=40, dt=50)
    rng = np.random.default_rng(0)
    p_tr = np.argsort(rng.random((6, 70)), axis=1)
    p_te = np.argsort(rng.random((6, 40)), axis=1)
    args = (v_tr, t_tr, y_tr, v_te, t_te, 1e-3, p_tr, p_te)
    capped, info = concat_ridge_permuted(*args, solver="pcg", max_iter=3, deflate=4)
    assert info == {"pcg_iterations": 3, "cholesky_solves": 6}  # none converged: all direct
    direct, _ = concat_ridge_permuted(*args, solver="cholesky")
    pcg, info = concat_ridge_permuted(*args, solver="pcg", max_iter=500)
    assert info["cholesky_solves"] == 0
    np.testing.assert_allclose(capped, direct, rtol=1e-12)
    np.testing.assert_allclose(pcg, direct, rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize("deflate", [0, 3, 20, 64])
def test_pcg_preconditioner_any_deflation_converges_to_cholesky(deflate):
    """The deflated preconditioner is SPD for every rank kept: the solution never depends on
    it; keeping every direction of both blocks makes it exact (one or two iterations)."""
    v_tr, t_tr, y_tr, v_te, t_te, _ = control_data(n_tr=90, dv=40, dt=60, seed=3)
    v_tr = v_tr * (1.0 / (1.0 + np.arange(40)))  # decaying spectra, like frozen ViT features
    t_tr = t_tr * (3.0 / np.sqrt(1.0 + np.arange(60)))
    rng = np.random.default_rng(1)
    p_tr = np.argsort(rng.random((7, 90)), axis=1)
    p_te = np.argsort(rng.random((7, 40)), axis=1)
    args = (v_tr, t_tr, y_tr, v_te, t_te, 0.5, p_tr, p_te)
    direct, _ = concat_ridge_permuted(*args, solver="cholesky")
    # residual tolerance far below the default 1e-10: the claim is convergence to the same
    # solution, so the comparison must not hinge on kappa x 1e-10 and this CPU's rounding
    pcg, info = concat_ridge_permuted(*args, tol=1e-13, max_iter=400, deflate=deflate)
    assert info["cholesky_solves"] == 0
    np.testing.assert_allclose(pcg, direct, rtol=1e-8, atol=1e-9)
    if deflate >= 60:
        assert info["pcg_iterations"] <= 2


def test_tactile_permutation_generic_fusion_and_logistic():
    v_tr, t_tr, y_tr, v_te, t_te, y_te = control_data(dt=6)
    c_tr, c_te = (y_tr > 0).astype(int), (y_te > 0).astype(int)
    rows = PairedRows(v_tr, t_tr, c_tr, v_te, t_te, c_te, fusion="mean")
    kw = dict(probe=FixedLogistic(1.0), metric="accuracy", n_permutations=5, seed=1)
    out = tactile_permutation_control(rows, **kw)
    again = tactile_permutation_control(rows, **kw)
    assert out["solver"] == {"refits": 5}  # mean fusion is not linear in the blocks: a loop
    assert np.array_equal(out["deltas"], again["deltas"])  # seeded => identical
    assert out["deltas"].shape == (5,) and np.isfinite(out["deltas"]).all()


def refit_deltas(data, fits, lam_v: float, lam_vt: float) -> list[float]:
    """The loop a batched control must equal: per (train rows, their labels) of `fits`, the
    test R² of the concat V+T ridge at `lam_vt` minus the V ridge's at `lam_v`, both refitted
    on those rows."""
    v_tr, t_tr, y_tr, v_te, t_te, y_te = data
    x_tr, x_te = fuse("concat", v_tr, t_tr), fuse("concat", v_te, t_te)
    return [
        r2_score(y_te, FixedRidge(lam_vt).fit_predict(x_tr[rows], y_tr[labels], x_te))
        - r2_score(y_te, FixedRidge(lam_v).fit_predict(v_tr[rows], y_tr[labels], v_te))
        for rows, labels in fits
    ]


def test_label_permutation_batched_equals_loop():
    data = control_data()
    probes = dict(probe_v=FixedRidge(1.0), probe_vt=FixedRidge(3.0), metric="r2")
    out = label_permutation_control(PairedRows(*data), **probes, n_permutations=10, seed=6)
    perm = np.argsort(np.random.default_rng(6).random((10, 70)), axis=1, kind="stable")
    ref = refit_deltas(data, [(slice(None), p) for p in perm], 1.0, 3.0)
    np.testing.assert_allclose(out["deltas"], ref, rtol=1e-9, atol=1e-12)
    assert out["vt_score_mean"] < 0.2  # permuted labels carry nothing to the test rows


def test_random_feature_control_is_seeded_and_dimension_matched():
    v_tr, t_tr, y_tr, v_te, t_te, y_te = control_data()
    kw = dict(probe=FixedRidge(1.0), metric="r2", n_draws=4, seed=2)
    a = random_feature_control(PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te), **kw)
    b = random_feature_control(PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te), **kw)
    assert np.array_equal(a["deltas"], b["deltas"])
    rng = np.random.default_rng(2)
    mu, sd = t_tr.mean(axis=0), t_tr.std(axis=0)
    r_tr = mu + sd * rng.standard_normal(t_tr.shape)
    r_te = mu + sd * rng.standard_normal(t_te.shape)
    pred = FixedRidge(1.0).fit_predict(np.hstack([v_tr, r_tr]), y_tr, np.hstack([v_te, r_te]))
    v_only = r2_score(y_te, FixedRidge(1.0).fit_predict(v_tr, y_tr, v_te))
    assert a["deltas"][0] == pytest.approx(r2_score(y_te, pred) - v_only, rel=1e-10)


def test_train_resample_diagnostic_equals_loop():
    data = control_data()
    probes = dict(probe_v=FixedRidge(1.0), probe_vt=FixedRidge(1.0), metric="r2")
    out = train_resample_diagnostic(PairedRows(*data), **probes, n_resamples=8, seed=3)
    idx = resample_indices(70, 8, seed=3)
    ref = refit_deltas(data, [(i, i) for i in idx], 1.0, 1.0)
    np.testing.assert_allclose(out["deltas"], ref, rtol=1e-10)
    assert out["delta_sd"] > 0


@pytest.mark.parametrize(
    "delta,ci_low,ctrl,expected",
    [
        (0.05, 0.01, 0.0, True),
        (0.03, 0.001, 0.0, True),  # boundary: Delta >= 0.03
        (0.029, 0.01, 0.0, False),
        (0.05, 0.0, 0.0, False),  # lower CI must be > 0
        (0.05, 0.01, 0.05, False),  # control must stay below Delta
    ],
)
def test_paper_criterion(delta, ci_low, ctrl, expected):
    assert paper_criterion(delta, ci_low, ctrl) is expected


def test_criterion_and_bootstrap_refuse_non_finite():
    with pytest.raises(ValueError, match="ci_low is nan"):
        paper_criterion(0.1, float("nan"), 0.0)
    y, pv, pvt = make_preds(10)
    pv[3] = np.inf
    with pytest.raises(ValueError, match="pred_v is non-finite at test row 3"):
        fixed_test_bootstrap(y, pv, pvt, "r2", 10, seed=0)
    ids = [f"t-{i}" for i in range(10)]
    with pytest.raises(ValueError, match="pred_v is non-finite at test sample_id 't-3'"):
        fixed_test_bootstrap(y, pv, pvt, "r2", 10, sample_ids=ids, seed=0)
    with pytest.raises(ValueError, match="metric must be"):
        fixed_test_bootstrap(y, pvt, pvt, "mse", 10, seed=0)


# ------------------------------------------------------------------ batched logistic controls

# Both paths at the optimum, so their labels are compared exactly although the batched
# solver and scikit-learn's lbfgs are different computations: at tol 1e-10 their decision
# values agree within 2e-6 on the problems below (measured: 3e-7 to 1.9e-6, against 3e-5 at
# tol 1e-6), while no test row lies within TIE_MARGIN of the boundary (`tight_predict` checks
# it in every reference fit): 50x apart; another CPU moves each stop within the same
# tolerance, so no label can flip.
TIGHT = FixedLogistic(1.0, tol=1e-10)
#: the V and the V+T probe of the logistic controls' tests, scored by accuracy
TIGHT_PAIR = dict(probe_v=TIGHT, probe_vt=TIGHT, metric="accuracy")
#: how far from a tie every test row's decision must lie for the labels of two solvers
#: stopped at TIGHT's tolerance to be compared exactly
TIE_MARGIN = 1e-4


def tight_predict(X_train, y_train, X_test):
    """`TIGHT.fit_predict` (the same fit), after checking that no test row's decision (|d|;
    with more classes the gap of the two largest logits) lies within TIE_MARGIN of a tie."""
    fit = fit_logistic_once(
        np.asarray(X_train, dtype=np.float64),
        np.asarray(y_train),
        TIGHT.C,
        TIGHT.max_iter,
        TIGHT.max_iter_cap,
        TIGHT.tol,
    )
    x_te = np.asarray(X_test, dtype=np.float64)
    d = fit.model.decision_function(x_te)
    top2 = np.sort(d, axis=1)[:, -2:] if d.ndim == 2 else None
    margin = np.abs(d) if top2 is None else top2[:, 1] - top2[:, 0]
    assert margin.min() > TIE_MARGIN, margin.min()
    return fit.model.predict(x_te)


#: `tight_predict` as a probe for `SpyProbe`'s refit loop
CHECKED_TIGHT = SimpleNamespace(fit_predict=tight_predict)


def class_data(n_tr=80, n_te=40, seed=0, n_classes=2):
    v_tr, t_tr, y_tr, v_te, t_te, y_te = control_data(n_tr, n_te, dv=4, dt=5, seed=seed)
    cuts = [-0.6, 0.6] if n_classes == 3 else [0.0]
    return v_tr, t_tr, np.digitize(y_tr, cuts), v_te, t_te, np.digitize(y_te, cuts)


@pytest.mark.parametrize("n_classes", [2, 3])
def test_logistic_tactile_permutation_batched_equals_refit_loop(n_classes):
    v_tr, t_tr, y_tr, v_te, t_te, y_te = class_data(n_classes=n_classes)
    kw = dict(metric="accuracy", n_permutations=6, seed=4, probe=TIGHT)
    fast = tactile_permutation_control(PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te), **kw)
    assert fast["solver"] == {"batched_logistic": 6}  # one shared design: batched
    rng = np.random.default_rng(4)  # training permutations only; test T intact
    p_tr = np.argsort(rng.random((6, 80)), axis=1, kind="stable")
    loop = [
        accuracy_score(
            y_te,
            tight_predict(fuse("concat", v_tr, t_tr[a]), y_tr, fuse("concat", v_te, t_te)),
        )
        for a in p_tr
    ]
    np.testing.assert_array_equal(fast["vt_scores"], loop)


def test_logistic_label_permutation_batched_equals_refit_loop():
    data = class_data(n_classes=3, seed=1)
    v_tr, t_tr, y_tr, v_te, t_te, y_te = data
    x_tr, x_te = fuse("concat", v_tr, t_tr), fuse("concat", v_te, t_te)
    out = label_permutation_control(PairedRows(*data), **TIGHT_PAIR, n_permutations=6, seed=6)
    perm = np.argsort(np.random.default_rng(6).random((6, 80)), axis=1, kind="stable")
    vt = [accuracy_score(y_te, tight_predict(x_tr, y_tr[p], x_te)) for p in perm]
    v = [accuracy_score(y_te, tight_predict(v_tr, y_tr[p], v_te)) for p in perm]
    np.testing.assert_array_equal(out["vt_scores"], vt)
    np.testing.assert_array_equal(out["v_scores"], v)


def test_logistic_random_features_batched_equals_refit_loop():
    v_tr, t_tr, y_tr, v_te, t_te, y_te = class_data(seed=2)
    kw = dict(metric="accuracy", n_draws=4, seed=2)
    fast = random_feature_control(PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te), probe=TIGHT, **kw)
    rng = np.random.default_rng(2)
    mu, sd = t_tr.mean(axis=0), t_tr.std(axis=0)
    loop = []
    for _ in range(4):
        r_tr = mu + sd * rng.standard_normal(t_tr.shape)
        r_te = mu + sd * rng.standard_normal(t_te.shape)
        pred = tight_predict(np.hstack([v_tr, r_tr]), y_tr, np.hstack([v_te, r_te]))
        loop.append(accuracy_score(y_te, pred))
    np.testing.assert_array_equal(fast["vt_scores"], loop)


def test_logistic_train_resample_batched_equals_loop_with_missing_class_resamples():
    v_tr, t_tr, y_tr, v_te, t_te, y_te = class_data(n_tr=30, n_classes=3, seed=3)
    y_tr = y_tr.copy()
    y_tr[:] = np.where(y_tr == 2, 1, y_tr)
    y_tr[:2] = 2  # a class of two rows: about one resample in eight misses it
    x_tr, x_te = fuse("concat", v_tr, t_tr), fuse("concat", v_te, t_te)
    rows = PairedRows(v_tr, t_tr, y_tr, v_te, t_te, y_te)
    out = train_resample_diagnostic(rows, **TIGHT_PAIR, n_resamples=16, seed=3)
    idx = resample_indices(30, 16, seed=3)
    missing = [len(np.unique(y_tr[i])) < 3 for i in idx]
    assert any(missing) and not all(missing)  # both paths are exercised
    vt = [accuracy_score(y_te, tight_predict(x_tr[i], y_tr[i], x_te)) for i in idx]
    v = [accuracy_score(y_te, tight_predict(v_tr[i], y_tr[i], v_te)) for i in idx]
    np.testing.assert_array_equal(out["vt_scores"], vt)
    np.testing.assert_array_equal(out["v_scores"], v)


def test_logistic_controls_batch_only_where_the_shared_preconditioner_fits():
    """Shared unweighted designs always batch (any number of classes); designs that vary per
    problem (bootstrap weights, random blocks) batch only with at least as many rows as
    columns; ridge never goes through the logistic batch."""
    y = np.repeat([0, 1, 2], 10)
    rng = np.random.default_rng(0)
    x30, x31 = rng.standard_normal((30, 30)), rng.standard_normal((30, 31))
    perm = np.argsort(rng.random((4, 30)), axis=1)

    def refits(x, **kw):
        return Refits((DesignBlock(x),), (DesignBlock(x[:5]),), y, **kw)

    rows = resample_indices(30, 4, seed=0)
    assert TIGHT.batches(refits(x31))  # shared unweighted design: any width
    assert TIGHT.batches(
        Refits(
            (DesignBlock(x31), DesignBlock(x31, perm)),
            (DesignBlock(x31[:5]), DesignBlock(x31[:5], perm[:, :5])),
            y,
        )
    )
    assert TIGHT.batches(refits(x30, rows=rows))
    assert not TIGHT.batches(refits(x31, rows=rows))
    assert not TIGHT.batches(
        Refits(
            (DesignBlock(x30), DesignBlock(x30, perm)),
            (DesignBlock(x30[:5]), DesignBlock(x30[:5], perm[:, :5])),
            y,
            fusion="mean",
        )
    )
    assert not FixedRidge(1.0).batches(refits(x30, rows=rows))  # ridge: its own paths only
    v_tr, t_tr, y_tr, v_te, t_te, y_te = class_data(n_tr=12, n_classes=3, seed=5)
    wide_tr, wide_te = np.hstack([v_tr, v_tr**2, t_tr]), np.hstack([v_te, v_te**2, t_te])
    # 13 columns > 12 rows: the train resamples take the refit loop and equal scikit-learn
    out = train_resample_diagnostic(
        PairedRows(v_tr, np.hstack([v_tr**2, t_tr]), y_tr, v_te, np.hstack([v_te**2, t_te]), y_te),
        probe_v=TIGHT,
        probe_vt=TIGHT,
        metric="accuracy",
        n_resamples=4,
        seed=5,
    )
    idx = resample_indices(12, 4, seed=5)
    vt = [accuracy_score(y_te, TIGHT.fit_predict(wide_tr[i], y_tr[i], wide_te)) for i in idx]
    np.testing.assert_array_equal(out["vt_scores"], vt)
