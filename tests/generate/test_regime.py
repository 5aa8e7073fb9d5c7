"""The regime (tacgen_lib.generate.regime, regime_generators): disjoint nested sets drawn from
the split, sizes refused before anything runs, the probes on tiny labelled sets (a missing
class, a class of one row, fewer rows than features) against scikit-learn, generalised
distillation against its pieces refitted with scikit-learn, the vision ceiling at rho = 0 and
rho = 1 exactly, and every arm of every cell on a synthetic world."""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from generate_worlds import small_probes
from sklearn.linear_model import LogisticRegression, Ridge
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import LeakageError
from tacgen_lib.generate.ladder import LADDER, ladder_rungs
from tacgen_lib.generate.regime import (
    ARMS,
    SUMMARY_COLUMNS,
    RegimeSets,
    RegimeSettings,
    RegimeTarget,
    SmallFit,
    appearance_design,
    assert_regime_disjoint,
    check_regime_sizes,
    distillation_rows,
    draw_regime_sets,
    evaluate_regime,
    fit_small_probe,
    gap_closed,
    job_regime_sets,
)
from tacgen_lib.generate.regime_arms import cell_rows, headroom_captured
from tacgen_lib.generate.regime_generators import pool_generators, pool_pairs, pool_steps
from tacgen_lib.generate.regime_sets import (
    natural_corpus_name,
    natural_grid_ends,
    regime_corpora,
)
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.visibility import VisibilitySettings
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap, resample_indices, score_interval
from tacgen_lib.probes.rows import family_rows
from tacgen_lib.probes.settings import ProbeSettings

N_CLASSES = 6


def probe_settings(kind: str) -> ProbeSettings:
    return small_probes(kind, [0.1, 1, 10, 100], [0.1, 1, 10], controls=2, seed=42)


def world(n: int = 240, *, rho: float, seed: int = 0, d_v: int = 10, d_t: int = 6):
    """A natural-design world: material m, appearance a = m with probability rho (else
    uniform); V a nonlinear (circular) code of a plus noise; T a noisy code of hardness and
    density (touch sees them); hardness soft for classes 0, 1; log mass from the class."""
    rng = np.random.default_rng(seed)
    m = rng.integers(N_CLASSES, size=n)
    a = np.where(rng.random(n) < rho, m, rng.integers(N_CLASSES, size=n))
    angle = 2 * np.pi * a / N_CLASSES
    v = np.column_stack([np.cos(angle), np.sin(angle)]) @ rng.normal(size=(2, d_v))
    v += 0.3 * rng.normal(size=(n, d_v))
    hard = np.where(m < 2, "soft", "hard")
    log_density = np.log([300, 1100, 650, 1200, 2400, 7800])[m]
    scale = rng.uniform(0.02, 0.04, size=n)
    log_mass = log_density + 3 * np.log(scale) + 0.1 * rng.normal(size=n)
    t = np.column_stack([(m < 2).astype(float), log_density / 5]) @ rng.normal(size=(2, d_t))
    t += 0.2 * rng.normal(size=(n, d_t))
    ids = np.array([f"nat-{i:04d}" for i in range(n)], dtype=object)
    split = np.array(["train"] * n, dtype=object)
    split[rng.permutation(n)[: n // 5]] = "test"
    manifest = pd.DataFrame(
        {
            "sample_id": ids,
            "corpus": "nat",
            "hardness": hard,
            "mass": np.exp(log_mass),
            "appearance_id": a,
            "shape": "cube",
            "scale": scale,
        }
    )
    splits = pd.DataFrame({"sample_id": ids, "corpus": "nat", "split": split})
    vision = dict(zip(ids, v, strict=True))
    tactile = dict(zip(ids, t, strict=True))
    return manifest, splits, vision, tactile


# --------------------------------------------------------------------------- sets


def test_sets_are_disjoint_nested_and_seeded():
    _, splits, _, _ = world(rho=1.0)
    a = draw_regime_sets(splits, "nat", n_labelled=40, n_pool=100, seed=3)
    b = draw_regime_sets(splits, "nat", n_labelled=40, n_pool=100, seed=3)
    c = draw_regime_sets(splits, "nat", n_labelled=40, n_pool=100, seed=4)
    assert list(a.labelled) == list(b.labelled) and list(a.pool) == list(b.pool)
    assert list(a.labelled) != list(c.labelled)
    assert set(a.test) == set(splits.loc[splits["split"] == "test", "sample_id"])
    assert not (set(a.labelled) & set(a.pool)) and not (set(a.pool) & set(a.test))
    assert not (set(a.labelled) & set(a.test))
    # nested: the smaller sets are prefixes
    assert list(a.labelled_ids(8)) == list(a.labelled[:8])
    assert set(a.pool_ids(10)) <= set(a.pool_ids(50))
    assert_regime_disjoint(a, splits, rule="test")


def test_labelled_draws_share_the_pool_and_never_touch_it_or_the_test_rows():
    _, splits, _, _ = world(rho=1.0)
    s = draw_regime_sets(splits, "nat", n_labelled=40, n_pool=100, seed=3)
    assert list(s.labelled_draw(0)) == list(s.labelled)  # draw 0 is today's labelled set
    d1, d2 = s.labelled_draw(1), s.labelled_draw(2)
    assert len(d1) == len(d2) == 40 and list(d1) != list(d2) and list(d1) != list(s.labelled)
    assert list(s.labelled_draw(1)) == list(d1)  # seeded
    rest = set(map(str, s.labelled)) | set(map(str, s.spare))
    for d in (d1, d2):
        assert set(map(str, d)) <= rest
        assert not set(map(str, d)) & (set(map(str, s.pool)) | set(map(str, s.test)))
    assert list(s.labelled_ids(8, draw=2)) == list(d2[:8])  # nested within a draw
    assert set(map(str, s.labelled_union(3))) == set(map(str, s.labelled)) | set(
        map(str, d1)
    ) | set(map(str, d2))
    assert_regime_disjoint(s, splits, rule="test", draws=3)
    # a later draw holding a pool row is refused
    bad = RegimeSets(s.labelled, s.pool, s.test, spare=s.pool[:5], seed=3)
    with pytest.raises(LeakageError, match="labelled and pool"):
        assert_regime_disjoint(bad, splits, rule="test", draws=3)


def test_a_job_draws_the_largest_sets_and_refuses_overlapping_ones(monkeypatch):
    from tacgen_lib.generate import regime_sets

    _, splits, _, _ = world(rho=1.0)
    regime = RegimeSettings(n_labelled=(8, 40), n_pool=(20, 100))
    got = job_regime_sets(splits, "nat", regime, 3, rule="regime_evaluate")
    want = draw_regime_sets(splits, "nat", n_labelled=40, n_pool=100, seed=3)
    assert list(got.labelled) == list(want.labelled) and list(got.pool) == list(want.pool)
    # a draw whose pool took a test row is refused, naming the rule
    bad = RegimeSets(want.labelled, np.concatenate([want.pool, want.test[:1]]), want.test, seed=0)
    monkeypatch.setattr(regime_sets, "draw_regime_sets", lambda *a, **k: bad)
    with pytest.raises(LeakageError, match="rule regime_evaluate"):
        job_regime_sets(splits, "nat", regime, 3, rule="regime_evaluate")


def test_sizes_that_cannot_be_drawn_disjointly_are_refused_naming_the_corpus():
    with pytest.raises(ValueError, match=r"corpus 'nat' has 48 non-test rows .*need 52"):
        check_regime_sizes("nat", 60, 12, [8, 16], [36])
    check_regime_sizes("nat", 60, 12, [8, 16], [32])  # exactly enough
    _, splits, _, _ = world(n=60, rho=0.0)
    with pytest.raises(ValueError, match="corpus 'nat'"):
        draw_regime_sets(splits, "nat", n_labelled=40, n_pool=40, seed=0)


def test_overlapping_or_held_out_rows_are_refused():
    _, splits, _, _ = world(rho=1.0)
    s = draw_regime_sets(splits, "nat", n_labelled=10, n_pool=20, seed=0)
    overlap = RegimeSets(s.labelled, np.concatenate([s.pool, s.labelled[:1]]), s.test, seed=0)
    with pytest.raises(LeakageError, match=f"labelled and pool .*{s.labelled[0]}"):
        assert_regime_disjoint(overlap, splits, rule="regime_generators")
    test_in_pool = RegimeSets(s.labelled, np.concatenate([s.pool, s.test[:1]]), s.test[1:], seed=0)
    with pytest.raises(LeakageError, match="regime_generators.*'test'"):
        assert_regime_disjoint(test_in_pool, splits, rule="regime_generators")


def test_pool_pairs_split_in_order_and_shuffled_pairs_break_every_pair():
    pool = [f"p{i}" for i in range(20)]
    train, val = pool_pairs(pool, val_fraction=0.1, pairing="real", seed=0)
    assert [v for v, _ in val] == ["p0", "p1"] and all(v == t for v, t in train + val)
    s_train, s_val = pool_pairs(pool, val_fraction=0.1, pairing="shuffled", seed=0)
    assert [v for v, _ in s_train] == [v for v, _ in train]
    assert sorted(t for _, t in s_train) == sorted(t for _, t in train)  # same marginal
    assert all(v != t for v, t in s_train + s_val)
    assert pool_pairs(pool, val_fraction=0.1, pairing="shuffled", seed=0) == (s_train, s_val)
    two = pool_pairs(["a", "b"], val_fraction=0.1, pairing="real", seed=0)
    assert two == ([("b", "b")], [("a", "a")])
    with pytest.raises(ValueError, match="a pool needs >= 2 rows"):
        pool_pairs(["a"], val_fraction=0.1, pairing="real", seed=0)


# --------------------------------------------------------------------------- probes


def test_pool_generators_in_workers_sample_what_one_process_samples():
    """Every (pool size, pairing) generator trained in a forked worker (one torch thread)
    samples bit for bit what it samples in this process under one torch thread."""
    import torch

    _, splits, vision, tactile = world(rho=1.0, seed=11)
    sets = draw_regime_sets(splits, "nat", n_labelled=20, n_pool=100, seed=0)
    settings = GenerateSettings(hidden=32, blocks=1, time_dim=16, steps=30, batch_size=32)
    regime = RegimeSettings(
        n_labelled=(20,), n_pool=(60, 100), seeds=(0,), sampling_steps=5, gen_mean_samples=3
    )
    cells = [(60, "real"), (60, "shuffled"), (100, "real"), (100, "shuffled")]
    rows = sorted(str(i) for i in [*sets.labelled, *sets.test])

    def run(workers: int):
        return pool_generators(
            vision,
            tactile,
            sets,
            cells,
            settings,
            regime,
            rows=rows,
            seed=3,
            workers=workers,
            device="cpu",
        )

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpool_limits(1):
            alone = run(1)
    finally:
        torch.set_num_threads(threads)
    forked = run(2)
    assert [(g.n_pool, g.pairing) for g in forked] == cells
    for a, b in zip(alone, forked, strict=True):
        assert a.t_gen.shape == a.t_gen_mean.shape == (len(rows), 6)
        assert np.array_equal(a.t_gen, b.t_gen) and a.curve == b.curve
        assert np.array_equal(a.t_gen_mean, b.t_gen_mean)
    assert not np.array_equal(forked[2].t_gen, forked[3].t_gen)  # real vs re-paired pool
    # the mean of 3 samples is not one sample, and spreads less around it
    assert not np.array_equal(alone[0].t_gen_mean, alone[0].t_gen)


def test_the_step_cap_grows_with_the_pool_above_the_reference_size():
    """steps x max(1, N_P / reference) ^ exponent: today's cap up to the reference pool (the
    default config's pool of 1024 rows keeps its 1000 steps), the same epochs above it at
    exponent 1, the square root of the growth at 0.5, no growth at 0."""
    regime = RegimeSettings()
    assert (regime.steps, regime.steps_reference_pool) == (1000, 1024)
    assert [pool_steps(1000, n, regime) for n in (24, 512, 1024)] == [1000] * 3
    assert pool_steps(1000, 4096, regime) == 4000 and pool_steps(1000, 1536, regime) == 1500
    assert pool_steps(1000, 4096, replace(regime, steps_pool_exponent=0.5)) == 2000
    assert pool_steps(1000, 4096, replace(regime, steps_pool_exponent=0.0)) == 1000
    assert pool_steps(40, 24, RegimeSettings(steps_reference_pool=12)) == 80


def test_pool_generators_train_a_larger_pool_for_more_steps():
    """Without early stopping each pool's generator runs its own cap (`pool_steps`)."""
    _, splits, vision, tactile = world(rho=1.0, seed=11)
    sets = draw_regime_sets(splits, "nat", n_labelled=20, n_pool=60, seed=0)
    settings = GenerateSettings(
        hidden=16, blocks=1, time_dim=8, steps=6, batch_size=16, eval_every=2, patience=0
    )
    regime = RegimeSettings(
        n_labelled=(20,),
        n_pool=(30, 60),
        sampling_steps=2,
        gen_mean_samples=1,
        steps_reference_pool=30,
    )
    rows = sorted(str(i) for i in sets.test)
    small, large = pool_generators(
        vision,
        tactile,
        sets,
        [(30, "real"), (60, "real")],
        settings,
        regime,
        rows=rows,
        seed=1,
        device="cpu",
    )
    assert (small.steps_run, large.steps_run) == (6, 12)


def test_the_mean_of_one_sample_is_that_sample():
    """K = 1: the ladder's gen_mean rung is the one-sample arm's T_gen, within float32
    rounding of a mean over one float64 copy."""
    _, splits, vision, tactile = world(rho=1.0, seed=11)
    sets = draw_regime_sets(splits, "nat", n_labelled=20, n_pool=60, seed=0)
    settings = GenerateSettings(hidden=16, blocks=1, time_dim=8, steps=10, batch_size=16)
    regime = RegimeSettings(
        n_labelled=(20,), n_pool=(60,), seeds=(0,), sampling_steps=3, gen_mean_samples=1
    )
    rows = sorted(str(i) for i in sets.test)
    (fit,) = pool_generators(
        vision, tactile, sets, [(60, "real")], settings, regime, rows=rows, seed=1, device="cpu"
    )
    np.testing.assert_array_equal(fit.t_gen_mean, fit.t_gen)


def test_a_single_labelled_class_predicts_that_class():
    x = np.random.default_rng(0).normal(size=(5, 3))
    got = fit_small_probe(
        x, np.array(["hard"] * 5, dtype=object), x[:2], probe_settings("logistic")
    )
    assert list(got.pred) == ["hard", "hard"] and math.isnan(got.reg)
    assert got.source.startswith("single class")


def test_a_class_of_one_row_fits_the_middle_C_as_scikit_learn_does():
    rng = np.random.default_rng(1)
    x, x_te = rng.normal(size=(9, 4)), rng.normal(size=(30, 4))
    y = np.array(["hard"] * 8 + ["soft"], dtype=object)
    got = fit_small_probe(x, y, x_te, probe_settings("logistic"))
    assert got.reg == 1.0 and got.source.startswith("fixed C")
    ref = LogisticRegression(C=1.0, tol=1e-10, max_iter=10000)
    scaler = StandardScaler().fit(x)
    ref.fit(scaler.transform(x), y)
    want = ref.predict(scaler.transform(x_te))
    # lbfgs to 1e-6 against 1e-10: labels agree wherever the margin is not at rounding level
    margin = np.abs(ref.decision_function(scaler.transform(x_te)))
    assert (got.pred[margin > 1e-4] == want[margin > 1e-4]).all()


def test_ridge_on_fewer_rows_than_features_is_closed_form_float64_ridge():
    rng = np.random.default_rng(2)
    x, x_te = rng.normal(size=(8, 20)), rng.normal(size=(15, 20))
    y = x @ rng.normal(size=20) + 0.1 * rng.normal(size=8)
    got = fit_small_probe(x, y, x_te, probe_settings("ridge"))
    ref = Ridge(alpha=got.reg, solver="svd").fit(x, y).predict(x_te)
    np.testing.assert_allclose(got.pred, ref, rtol=1e-8, atol=1e-8)


def test_distillation_is_a_v_only_student_of_the_teachers_pool_labels():
    manifest, splits, vision, tactile = world(rho=1.0, seed=5)
    sets = draw_regime_sets(splits, "nat", n_labelled=30, n_pool=120, seed=0)
    ps = probe_settings("ridge")
    y = dict(zip(manifest["sample_id"], np.log(manifest["mass"]), strict=True))
    lab, pool, test = sets.labelled, sets.pool, sets.test

    def block(src, ids):
        return np.stack([src[i] for i in ids])

    x_d, y_d = distillation_rows(
        block(vision, lab),
        block(tactile, lab),
        np.array([y[i] for i in lab]),
        block(vision, pool),
        block(tactile, pool),
        ps,
    )
    got = fit_small_probe(x_d, y_d, block(vision, test), ps)  # the linear student
    # the pieces refitted with scikit-learn at the penalties the probes chose
    teacher = fit_small_probe(
        np.hstack([block(vision, lab), block(tactile, lab)]),
        np.array([y[i] for i in lab]),
        np.hstack([block(vision, pool), block(tactile, pool)]),
        ps,
    )
    t_ref = Ridge(alpha=teacher.reg, solver="svd").fit(
        np.hstack([block(vision, lab), block(tactile, lab)]), [y[i] for i in lab]
    )
    np.testing.assert_allclose(
        teacher.pred,
        t_ref.predict(np.hstack([block(vision, pool), block(tactile, pool)])),
        rtol=1e-8,
        atol=1e-8,
    )
    x_all = np.vstack([block(vision, lab), block(vision, pool)])
    y_all = np.concatenate([[y[i] for i in lab], teacher.pred])
    np.testing.assert_array_equal(x_d, x_all)  # V only: the student never sees touch
    np.testing.assert_array_equal(y_d, y_all)
    s_ref = Ridge(alpha=got.reg, solver="svd").fit(x_all, y_all).predict(block(vision, test))
    np.testing.assert_allclose(got.pred, s_ref, rtol=1e-8, atol=1e-8)
    # a pool of one row still distils
    x_one, y_one = distillation_rows(
        block(vision, lab),
        block(tactile, lab),
        np.array([y[i] for i in lab]),
        block(vision, pool[:1]),
        block(tactile, pool[:1]),
        ps,
    )
    one = fit_small_probe(x_one, y_one, block(vision, test), ps)
    assert np.isfinite(one.pred.astype(float)).all()


@pytest.mark.parametrize("metric", ["accuracy", "r2"])
def test_cell_rows_are_the_pairwise_fixed_test_bootstrap(metric):
    # one count matrix for the whole cell gives each pair's fixed_test_bootstrap
    rng = np.random.default_rng(3)
    n = 90
    if metric == "accuracy":
        y = rng.choice(np.array(["hard", "soft"], dtype=object), n)

        def pred(p):  # right with probability p
            return np.where(rng.random(n) < p, y, np.where(y == "hard", "soft", "hard"))
    else:
        y = rng.normal(size=n)

        def pred(p):
            return y + (1.5 - p) * rng.normal(size=n)

    fits = {k: SmallFit(pred(0.5 + 0.05 * i), 1.0, "cv") for i, k in enumerate(ARMS)}
    idx = resample_indices(n, 500, 11)
    base = {"corpus": "c", "n_labelled": 32, "n_pool": 64, "seed": 0, "draw": 0, "target": "t"}
    base["majority"] = 0.5
    rows = cell_rows(fits, y, idx, metric, base=base)
    assert [(r["arm"], r["probe"]) for r in rows] == list(ARMS)
    # accuracy: integer counts, exact; R^2: sums over a count-matrix product of another
    # shape (10 arms against 1 or 2), equal within rounding on any CPU
    tol = {"rel": 0.0, "abs": 0.0} if metric == "accuracy" else {"rel": 1e-12, "abs": 1e-14}
    for r in rows:
        k = (r["arm"], r["probe"])
        want_ci = score_interval(metric, y, fits[k].pred, idx)
        assert (r["ci_low"], r["ci_high"]) == pytest.approx(want_ci, **tol)
        gd = ("distilled", "nonlinear" if k[1] == "nonlinear" else "linear")
        for ref, col in (
            (("v", "linear"), "linear_v"),
            (("v", "nonlinear"), "nonlinear_v"),
            (gd, "distilled"),
        ):
            want = fixed_test_bootstrap(
                y, fits[ref].pred, fits[k].pred, metric, len(idx), 0, indices=idx
            )
            assert r[f"delta_vs_{col}"] == want["delta"]
            assert r["score"] == want["vt_score"]
            got = (r[f"ci_low_vs_{col}"], r[f"ci_high_vs_{col}"])
            assert got == pytest.approx((want["ci_low"], want["ci_high"]), **tol)


def test_cell_rows_refuse_an_arm_with_a_missing_or_non_finite_prediction():
    y = np.linspace(0.0, 1.0, 20)
    fits = {k: SmallFit(y.copy(), 1.0, "cv") for k in ARMS}
    fits[("v_tgen", "linear")] = SmallFit(np.where(y > 0.5, np.nan, y), 1.0, "cv")
    base = {"corpus": "c", "n_labelled": 32, "n_pool": 64, "seed": 0, "draw": 0, "target": "t"}
    base["majority"] = 0.5
    with pytest.raises(ValueError, match="regime cell c N_L=32 t: arm v_tgen/linear"):
        cell_rows(fits, y, resample_indices(20, 10, 0), "r2", base=base)


def test_gap_closed():
    assert gap_closed(0.7, 0.5, 0.9) == pytest.approx(0.5)
    assert gap_closed(0.5, 0.5, 0.9) == 0.0
    assert math.isnan(gap_closed(0.7, 0.5, 0.5)) and math.isnan(gap_closed(0.7, 0.6, 0.5))


def test_headroom_captured_only_where_the_headroom_exceeds_its_noise():
    assert headroom_captured(0.7, 0.5, 0.9, 0.1) == pytest.approx(0.5)
    # a headroom whose paired CI reaches 0 (or below) gives no ratio, however large the arm
    assert math.isnan(headroom_captured(0.503, 0.5, 0.503, 0.0))
    assert math.isnan(headroom_captured(0.503, 0.5, 0.503, -0.01))
    assert math.isnan(headroom_captured(0.7, 0.5, 0.9, math.nan))


@pytest.mark.parametrize("ceiling_gain", [0.0, 0.4])
def test_cell_rows_give_headroom_captured_only_where_the_ceilings_ci_is_above_nonlinear_v(
    ceiling_gain,
):
    """The V ceiling +0.000 over nonlinear V on the same rows (its CI holds 0): every arm's
    headroom captured is NaN, even an arm above nonlinear V; a ceiling well above it: the
    ratio, as `gap_closed` against the ceiling."""
    rng = np.random.default_rng(4)
    n = 120
    y = rng.normal(size=n)
    nl = y + rng.normal(size=n)
    fits = {k: SmallFit(y + 0.8 * rng.normal(size=n), 1.0, "cv") for k in ARMS}
    fits[("v", "nonlinear")] = SmallFit(nl, 1.0, "cv")
    fits[("v_ceiling", "nonlinear")] = SmallFit(
        nl if ceiling_gain == 0 else y + 0.3 * rng.normal(size=n), 1.0, "cv"
    )
    base = {"corpus": "c", "n_labelled": 32, "n_pool": 64, "seed": 0, "draw": 0, "target": "t"}
    base["majority"] = 0.0
    rows = {
        (r["arm"], r["probe"]): r
        for r in cell_rows(fits, y, resample_indices(n, 300, 1), "r2", base=base)
    }
    ceiling = rows[("v_ceiling", "nonlinear")]
    arm = rows[("kernel_ridge", "linear")]
    if ceiling_gain == 0:
        assert ceiling["ci_low_vs_nonlinear_v"] <= 0
        assert all(math.isnan(r["headroom_captured"]) for r in rows.values())
    else:
        assert ceiling["ci_low_vs_nonlinear_v"] > 0
        want = gap_closed(arm["score"], rows[("v", "nonlinear")]["score"], ceiling["score"])
        assert arm["headroom_captured"] == pytest.approx(want, rel=1e-12)


# --------------------------------------------------------------------------- ceiling + arms


def _ceiling_accuracy(rho: float) -> float:
    manifest, splits, _, _ = world(n=600, rho=rho, seed=9)
    m = manifest.set_index("sample_id")
    train = splits.loc[splits["split"] != "test", "sample_id"]
    test = splits.loc[splits["split"] == "test", "sample_id"]
    x_tr, x_te = appearance_design(m.loc[train], m.loc[test], log_target=True, n_classes=6)
    fit = fit_small_probe(
        x_tr, m.loc[train, "hardness"].to_numpy(object), x_te, probe_settings("logistic")
    )
    return float(np.mean(fit.pred == m.loc[test, "hardness"].to_numpy(object)))


def test_vision_ceiling_is_perfect_at_rho_1_and_the_majority_at_rho_0():
    assert _ceiling_accuracy(1.0) == 1.0  # appearance = material decides hardness exactly
    majority = 4 / 6  # classes 2..5 are hard: at rho = 0 appearance says nothing
    assert abs(_ceiling_accuracy(0.0) - majority) < 0.1


def _evaluate(
    rho: float,
    *,
    n_labelled=(6, 40),
    t_gen_from_real: bool = False,
    workers=1,
    draws=2,
    control: bool = False,
):
    """The regime's rows on `world`; with `control`, as the positive control runs them: no
    generator (no gen_mean rung, no t_gen), no V ceiling, no generalised distillation."""
    manifest, splits, vision, tactile = world(rho=rho, seed=11)
    sets = draw_regime_sets(splits, "nat", n_labelled=max(n_labelled), n_pool=100, seed=0)
    ceiling_rows = manifest.set_index("sample_id")[["appearance_id", "shape", "scale"]]
    targets = []
    for target, kind in (("hardness", "logistic"), ("log_mass", "ridge")):
        rows = family_rows(manifest, splits, corpus="nat", target=target, kind=kind)
        targets.append(RegimeTarget(rows, probe_settings(kind), ceiling_rows))
    rng = np.random.default_rng(0)
    noisy = {i: v + 0.5 * rng.normal(size=v.shape) for i, v in tactile.items()}
    ids = list(tactile)
    shuffled = dict(zip(ids, [tactile[j] for j in np.roll(ids, 1)], strict=True))
    t_gen = {(100, "real"): tactile if t_gen_from_real else noisy, (100, "shuffled"): shuffled}
    # the world's look is its appearance class (the oracle's key)
    looks = manifest.set_index("sample_id")["appearance_id"].astype(str)
    rows = sorted(str(i) for i in [*sets.labelled_union(draws), *sets.test])
    rungs = ladder_rungs(
        vision,
        tactile,
        looks,
        sets.pool_ids(100),
        rows,
        None if control else noisy,
        regime=RegimeSettings(look_min_rows=1, knn_ks=(1, 2, 4, 8, 16, 32, 64)),
        seed=0,
    )
    return evaluate_regime(
        targets,
        sets,
        RegimeSettings(n_labelled=n_labelled, n_pool=(100,), bootstrap=200, label_draws=draws),
        None if control else VisibilitySettings(gammas=(0.5, 2.0), C=(1.0, 100.0)),
        corpus="nat",
        rho=rho,
        seed=0,
        vision=vision,
        t_real=tactile,
        t_gen={} if control else t_gen,
        ladder={100: rungs.t_gen},
        gammas=[0.5, 2.0],
        n_classes=6,
        workers=workers,
        distil=not control,
    )


@functools.cache
def _rows_of(rho: float) -> pd.DataFrame:
    """`_evaluate(rho)` computed once per module for the tests that read its rows; a test of
    reproducibility compares them with a computation of its own. Callers get a copy."""
    return _evaluate(rho)


def _regime_rows(rho: float) -> pd.DataFrame:
    return _rows_of(rho).copy()


def test_every_arm_of_every_cell_is_scored_and_reproducible():
    a = _regime_rows(1.0)
    assert list(a.columns) == list(SUMMARY_COLUMNS)
    assert len(a) == 2 * 2 * 2 * len(ARMS) and a["row_id"].is_unique  # targets x N_L x draws
    assert set(a["draw"]) == {0, 1}
    # the ceilings are fitted once per target: the same in every draw and N_L
    for (_t, arm, probe), g in a[a["arm"].isin(["v_ceiling", "vision_ceiling"])].groupby(
        ["target", "arm", "probe"]
    ):
        assert g["score"].nunique() == 1, (arm, probe)
    # the majority score is the constant prediction's, and the flag reads it
    assert (a["below_majority"] == (a["score"] < a["majority"])).all()
    assert set(zip(a["arm"], a["probe"], strict=True)) == set(ARMS)
    assert np.isfinite(a["score"]).all() and (a["ci_low"] <= a["ci_high"]).all()
    v = a[(a["arm"] == "v") & (a["probe"] == "linear")]
    assert (v["delta_vs_linear_v"] == 0).all() and (v["ci_low_vs_linear_v"] == 0).all()
    pd.testing.assert_frame_equal(a, _evaluate(1.0))  # the same computation twice: bit for bit


def test_the_positive_control_fits_only_the_arms_it_has_inputs_for():
    """No generator, no V ceiling, no distillation: the rungs that learn from the pool, V and
    V + real T, every row scored, and the Deltas against the missing arms NaN, not 0; the
    arms it shares with the full regime are the same fits on the same rows."""
    from tacgen_lib.generate.ladder import LADDER

    full, control = _regime_rows(1.0), _evaluate(1.0, control=True)
    kept = {("v", "linear"), ("v", "nonlinear"), ("v_treal", "linear")} | {
        (r, p) for r in LADDER if r not in ("gen_mean", "v_tgen") for p in ("linear", "nonlinear")
    }
    assert set(zip(control["arm"], control["probe"], strict=True)) == kept
    assert list(control.columns) == list(SUMMARY_COLUMNS) and control["row_id"].is_unique
    assert np.isfinite(control["score"]).all()
    assert control["delta_vs_distilled"].isna().all() and control["headroom_captured"].isna().all()
    same = full[full["row_id"].isin(control["row_id"])].reset_index(drop=True)
    shared = ["row_id", "score", "ci_low", "ci_high", "delta_vs_nonlinear_v", "gap_closed"]
    # the same fits, scored in a cell of fewer arms: the resampled scores are one matrix
    # product over the cell's arms, whose rounding may follow the number of columns on
    # other BLAS kernels, so the two agree within float rounding, not bit for bit
    pd.testing.assert_frame_equal(
        control[shared].sort_values("row_id", ignore_index=True),
        same[shared].sort_values("row_id", ignore_index=True),
        check_exact=False,
        rtol=1e-9,
        atol=1e-12,
    )


def test_forked_workers_give_the_rows_of_one_process_bit_for_bit():
    """Each (target, N_L) cell computes the same thing in a worker (one BLAS thread) as in
    the job's process under one BLAS thread: the rows do not depend on the workers."""
    with threadpool_limits(1):
        alone = _evaluate(1.0)
    pd.testing.assert_frame_equal(_evaluate(1.0, workers=2), alone)


def test_a_generator_that_returns_real_touch_scores_as_real_touch():
    a = _evaluate(1.0, t_gen_from_real=True)
    for (target, n_l, draw), g in a.groupby(["target", "n_labelled", "draw"]):
        real = g[g["arm"] == "v_treal"]["score"].iloc[0]
        gen = g[(g["arm"] == "v_tgen") & (g["probe"] == "linear")]["score"].iloc[0]
        assert gen == real, (target, n_l, draw)


def test_a_labelled_set_with_one_class_is_scored_not_refused():
    manifest, splits, *_ = world(rho=1.0, seed=11)
    sets = draw_regime_sets(splits, "nat", n_labelled=40, n_pool=100, seed=0)
    y = manifest.set_index("sample_id").loc[sets.labelled, "hardness"].to_numpy()
    first_two = len(set(y[:2]))
    a = _evaluate(1.0, n_labelled=(2, 40))
    hard = a[(a["target"] == "hardness") & (a["n_labelled"] == 2) & (a["draw"] == 0)]
    assert (hard["n_labelled_classes"] == first_two).all()
    assert np.isfinite(hard["score"]).all()


def test_findings_and_report_read_the_summary():
    import matplotlib

    matplotlib.use("Agg")
    from tacgen_lib.report import regime as rep
    from tacgen_lib.report.findings import regime_findings

    summary = pd.concat([_regime_rows(0.0), _regime_rows(1.0)], ignore_index=True)
    found, decided = regime_findings(summary)
    ids = {d["decision_id"] for d in decided}
    assert {"regime|hardness|v_tgen_vs_linear_v", "regime|hardness|positive_control"} <= ids
    assert list(found["evidence"]) == ["regime", "regime"]
    hard = found[found["question"].str.contains("hardness")].iloc[0]
    gen = summary[
        (summary["rho"] == 1.0)
        & (summary["n_labelled"] == 6)
        & (summary["target"] == "hardness")
        & (summary["arm"] == "v_tgen")
        & (summary["probe"] == "linear")
    ]
    # the mean over the cell's replicates (seed x labelled draw), not one draw
    assert len(gen) == 2
    assert f"{gen['delta_vs_linear_v'].mean():+.3f}" in hard["result"]
    assert "of 2 replicates" in hard["result"]
    assert "ρ = 1, N_L = 6, N_P = 100" in hard["question"]
    assert "look oracle − nonlinear V" in hard["control"]
    view = rep.seed_view(summary)
    assert len(view) == len(summary) // 2  # one seed, two draws: one row per cell x arm
    assert set(view["n_seeds"]) == {2}
    table = rep.regime_table(view)
    assert set(table["N_L"]) == {6, 40} and table["arm"].nunique() == len(ARMS)
    ladder = rep.ladder_table(view)
    assert set(ladder["rung"]) >= {"V + T_gen A0 look oracle (linear)", "V (nonlinear)"}
    notes = rep.findings_notes(view, ["V fails the visibility gate on nat: ..."], False)
    assert notes[0].startswith("V fails the visibility gate")
    assert any(n.startswith("Positive control") for n in notes)
    assert any(n.startswith("H1 (ρ = 0") for n in notes)
    assert any(n.startswith("H5") for n in notes)
    assert any(n.startswith("One pool size ran (N_P = 100): the curve against") for n in notes)
    assert set(rep.pool_table(view)["N_L"]) == {6, 40}
    for fig in (rep.heatmap_figure(view), rep.curves_figure(view), rep.pool_curve_figure(view)):
        assert fig.axes


def test_one_natural_corpus_per_rho_named_by_its_digits():
    assert [natural_corpus_name(r) for r in (0, 0.25, 0.5, 1)] == [
        "sim_natural_r0",
        "sim_natural_r025",
        "sim_natural_r05",
        "sim_natural_r1",
    ]
    base = {"kind": "simulated", "design": "natural", "n": 60, "seed": 13}
    got = regime_corpora({"corpus": base, "rhos": [0, 0.5]})
    assert got == {"sim_natural_r0": {**base, "rho": 0.0}, "sim_natural_r05": {**base, "rho": 0.5}}
    assert regime_corpora({"corpus": base, "rhos": []}) == {} == regime_corpora(None)
    with pytest.raises(ValueError, match="design natural"):
        regime_corpora({"corpus": {**base, "design": "paired"}, "rhos": [0]})
    with pytest.raises(ValueError, match="not in"):
        natural_corpus_name(1.5)


def test_the_corpora_between_the_grids_ends_are_named_only_when_both_ends_are_in_it():
    base = {"corpus": {"kind": "simulated", "design": "natural", "n": 10}}
    ends, between = natural_grid_ends({**base, "rhos": [0.5, 0, 0.25, 1]})
    assert ends == ["sim_natural_r0", "sim_natural_r1"]
    assert between == ["sim_natural_r05", "sim_natural_r025"]
    assert natural_grid_ends({**base, "rhos": [0, 0.5]}) == ([], [])
    assert natural_grid_ends({**base, "rhos": [0, 1]}) == (["sim_natural_r0", "sim_natural_r1"], [])
    assert natural_grid_ends(None) == ([], [])


def _ladder_summary(above: dict[tuple, bool], pools: tuple[int, ...] = (100,)) -> pd.DataFrame:
    """A regime summary of one target whose rungs (linear probe) beat nonlinear V with the CI
    above 0 in every replicate where `above[(rho, rung)]` (at every pool size) or
    `above[(rho, rung, n_pool)]` says so, else include 0."""
    from tacgen_lib.generate.ladder import LADDER

    rows = []
    for rho, n_l, n_p, draw in itertools.product((0.0, 1.0), (8, 64), pools, range(3)):
        for arm, probe in [("v", "nonlinear"), *((r, "linear") for r in LADDER)]:
            wins = above.get((rho, arm), False) or above.get((rho, arm, n_p), False)
            up = wins and n_l == 8
            d = 0.1 if up else 0.0
            rows.append(
                {
                    "corpus": f"nat{rho:g}",
                    "rho": rho,
                    "n_labelled": n_l,
                    "n_pool": n_p,
                    "seed": 0,
                    "draw": draw,
                    "target": "hardness",
                    "metric": "accuracy",
                    "arm": arm,
                    "probe": probe,
                    "score": 0.6 + d,
                    "ci_low": 0.5,
                    "ci_high": 0.8,
                    "gap_closed": np.nan,
                    "headroom_captured": np.nan,
                    "majority": 0.5,
                    "below_majority": False,
                    **{
                        f"{c}_vs_{w}": v
                        for w in ("linear_v", "nonlinear_v", "distilled")
                        for c, v in (
                            ("delta", d),
                            ("ci_low", 0.02 if up else -0.05),
                            ("ci_high", 0.2 if up else 0.05),
                        )
                    },
                }
            )
    return pd.DataFrame(rows)


def test_ladder_verdict_reads_the_control_then_the_rung_that_loses_the_gain():
    from tacgen_lib.report.regime import ladder_verdict, seed_view

    lost_at_knn = seed_view(_ladder_summary({(1.0, "look_oracle"): True}))
    words = ladder_verdict(lost_at_knn, ["gate sentence"], gate_passed=True)
    assert words[0] == "gate sentence"
    assert words[1].startswith("Positive control works (hardness, ρ = 1, N_L = 8, N_P = 100)")
    assert "lost at A1 kNN in V" in words[2] and "vision" in words[2]

    keep = {(1.0, r): True for r in LADDER}
    assert (
        "every rung down to one diffusion sample"
        in ladder_verdict(seed_view(_ladder_summary(keep)))[-1]
    )
    lost_at_sample = {k: v for k, v in keep.items() if k[1] != "v_tgen"}
    last = ladder_verdict(seed_view(_ladder_summary(lost_at_sample)), gate_passed=False)[-1]
    assert "lost at A3 one diffusion sample" in last and "failed the visibility gate" in last

    # no gain for the oracle, or a gain at rho = 0 too: the control fails and nothing more is said
    for above in ({}, {(1.0, "look_oracle"): True, (0.0, "look_oracle"): True}):
        words = ladder_verdict(seed_view(_ladder_summary(above)))
        assert len(words) == 1 and words[0].startswith("Positive control fails")


def test_the_page_gives_headroom_captured_only_where_the_ceilings_headroom_exceeds_its_noise():
    """The ladder table and the table of every arm: the mean headroom captured where the V
    ceiling's headroom over nonlinear V lies above 0 over the replicates, 'headroom within
    noise' where it does not (rho = 0 here: the ceiling's CI holds 0 in every replicate)."""
    from tacgen_lib.report.regime import WITHIN_NOISE, ladder_table, regime_table, seed_view

    s = _ladder_summary({(1.0, "look_oracle"): True}).assign(headroom_captured=0.25)
    ceiling = s[s["arm"] == "v"].assign(arm="v_ceiling", headroom_captured=np.nan)
    up = ceiling["rho"] == 1.0
    ceiling.loc[up, ["delta_vs_nonlinear_v", "ci_low_vs_nonlinear_v"]] = (0.1, 0.02)
    ceiling.loc[up, "ci_high_vs_nonlinear_v"] = 0.2
    ceiling.loc[~up, ["delta_vs_nonlinear_v", "ci_low_vs_nonlinear_v"]] = (0.003, -0.01)
    view = seed_view(pd.concat([s, ceiling], ignore_index=True))
    for table, col in ((ladder_table(view), "rung"), (regime_table(view), "arm")):
        rung = table[table[col].str.contains("kernel ridge V→T")]
        assert len(rung) == 4  # two rhos x two N_L
        for rho, cells in rung.groupby("ρ"):
            want = 0.25 if rho == "1" else WITHIN_NOISE
            assert list(cells["headroom captured"]) == [want, want]


def test_one_replicates_chance_gain_at_the_smallest_rho_does_not_undo_the_control():
    """At rho = 0 the look says nothing of the material; one replicate of three with its CI
    above 0 there is chance (about one in twenty each), not a gain: a gain is one every
    replicate shows, at either end of the grid. Every replicate above 0 there fails it."""
    from tacgen_lib.report.regime import ladder_verdict, seed_view

    s = _ladder_summary({(1.0, "look_oracle"): True})
    at_0 = (s["rho"] == 0.0) & (s["arm"] == "look_oracle") & (s["n_labelled"] == 8)
    one = s.copy()
    one.loc[at_0 & (one["draw"] == 0), "ci_low_vs_nonlinear_v"] = 0.01
    words = ladder_verdict(seed_view(one))
    assert words[0].startswith("Positive control works") and "1 of 3 replicates" in words[0]
    every = s.copy()
    every.loc[at_0, ["delta_vs_nonlinear_v", "ci_low_vs_nonlinear_v"]] = [0.1, 0.02]
    (failed,) = ladder_verdict(seed_view(every))
    assert failed.startswith("Positive control fails") and "too, where appearance" in failed


def test_the_pool_verdict_names_the_smallest_pool_where_each_kind_of_rung_gains():
    """Against the pool size: the smallest N_P at which a learnt rung and at which the
    diffusion model gain over nonlinear V in every replicate, the look oracle as the
    reference, and the smallest rho's curve as the flat control."""
    import matplotlib

    matplotlib.use("Agg")
    from tacgen_lib.report.regime import heatmap_figure, pool_curve_figure, pool_table, seed_view
    from tacgen_lib.report.regime_pool import first_gain, pool_verdict
    from tacgen_lib.report.write import figure_problems

    pools = (256, 1024, 4096)
    above = {
        (1.0, "look_oracle"): True,
        (1.0, "kernel_ridge", 1024): True,
        (1.0, "kernel_ridge", 4096): True,
        (1.0, "ridge", 4096): True,
    }
    view = seed_view(_ladder_summary(above, pools))
    # the highest rung on the ladder at the smallest pool where one gains
    assert first_gain(view, "hardness", 1.0, 8, ("knn", "ridge", "kernel_ridge")) == (
        1024,
        "kernel_ridge",
    )
    assert first_gain(view, "hardness", 1.0, 8, ("gen_mean", "v_tgen")) is None
    # every replicate's CI above 0 is not enough where the replicates' interval reaches 0
    spread = view.copy()
    at = (spread["arm"] == "kernel_ridge") & (spread["n_pool"] == 1024) & (spread["rho"] == 1.0)
    spread.loc[at, "rep_low_vs_nonlinear_v"] = -0.01
    assert int(spread.loc[at & (spread["n_labelled"] == 8), "above_vs_nonlinear_v"].iloc[0]) == 3
    assert first_gain(spread, "hardness", 1.0, 8, ("knn", "ridge", "kernel_ridge")) == (
        4096,
        "ridge",
    )
    assert first_gain(view, "hardness", 1.0, 64, ("look_oracle",)) is None  # only N_L = 8 gains
    curve, control = pool_verdict(view)
    assert "a learnt rung first gains over nonlinear V over the replicates at N_P = 1024" in curve
    assert "kernel ridge V→T: +0.100" in curve and "3 of 3 replicates" in curve
    assert "no diffusion rung (A2 diffusion mean, A3 one diffusion sample)" in curve
    assert "up to 4096" in curve and "the look oracle − nonlinear V at N_P = 4096: +0.100" in curve
    assert "flat, no rung gains" in control
    assert "The look oracle gains over the replicates at no pool size" not in curve
    no_oracle = {k: v for k, v in above.items() if k[1] != "look_oracle"}
    (void, _) = pool_verdict(seed_view(_ladder_summary(no_oracle, pools)))
    assert void.endswith("so the curve cannot show what a generator would add.")
    # a gain at the smallest rho, where the look says nothing of the material, is named
    (_, spoiled) = pool_verdict(
        seed_view(_ladder_summary({**above, (0.0, "v_tgen", 256): True}, pools))
    )
    assert "not flat: A3 one diffusion sample at N_P = 256 gain over the replicates" in spoiled
    # one pool size: no curve, said once
    (one,) = pool_verdict(seed_view(_ladder_summary(above, (100,))))
    assert one.startswith("One pool size ran (N_P = 100)")
    table = pool_table(view)
    assert [c for c in table if c.startswith("N_P")] == ["N_P = 256", "N_P = 1024", "N_P = 4096"]
    assert len(table) == 2 * 2 * 6  # rho x N_L x (the look oracle and five rungs)
    row = table[(table["ρ"] == "1") & (table["N_L"] == 8) & (table["rung"] == "kernel ridge V→T")]
    assert row["N_P = 256"].item().endswith("0/3 ↑, 0/3 ↓")
    assert row["N_P = 1024"].item().startswith("+0.100 [") and "3/3 ↑" in row["N_P = 1024"].item()
    fig = pool_curve_figure(view)
    assert len(fig.axes) == 2  # one target x (largest rho, smallest rho)
    assert sorted(fig.axes[0].get_xticks()) == list(pools)
    # both figures fit the report's viewer whatever the number of pool sizes (the heatmap
    # keeps the smallest and the largest pool, two columns)
    wide = seed_view(_ladder_summary(above, (256, 1024, 4096, 16384)))
    for fig in (pool_curve_figure(wide), heatmap_figure(wide)):
        assert figure_problems(fig) == []
    titles = [ax.get_title() for ax in heatmap_figure(wide).axes if ax.get_title()]
    assert {t.split(":")[0] for t in titles} == {"hardness, N_P = 256", "hardness, N_P = 16384"}


def test_the_pool_curve_is_read_where_the_look_oracle_gains():
    """On labelled sets too small for the probe to show even the look oracle's gain, no rung
    could show one: the verdict, the figure and the findings' decisions read the curve at the
    fewest labels on which the oracle gains (`reading_n_labelled`), and at the fewest where it
    gains at none; the table shows that N_L beside the smallest and the largest."""
    import matplotlib

    matplotlib.use("Agg")
    from tacgen_lib.report.findings_regime import _pool_decisions
    from tacgen_lib.report.regime import pool_curve_figure, pool_table, seed_view
    from tacgen_lib.report.regime_pool import pool_verdict, reading_n_labelled

    pools = (256, 1024, 4096)
    above = {(1.0, "look_oracle"): True, (1.0, "kernel_ridge", 1024): True}
    rows = _ladder_summary(above, pools)
    # the gains at N_L = 64 and none at 8: the oracle has no power on the fewer labels
    rows["n_labelled"] = rows["n_labelled"].map({8: 64, 64: 8})
    view = seed_view(rows)
    assert reading_n_labelled(view, "hardness", 1.0) == 64
    curve = pool_verdict(view)[0]
    assert (
        "N_L = 64" in curve
        and "first gains over nonlinear V over the replicates at N_P = 1024" in curve
    )
    titles = [ax.get_title() for ax in pool_curve_figure(view).axes]
    assert all(t.endswith("N_L = 64") for t in titles), titles
    learnt = [d for d in _pool_decisions(view, None) if d["decision_id"].endswith("learnt")]
    assert len(learnt) == 1 and "N_L = 64" in learnt[0]["what"]
    assert learnt[0]["decision"].startswith("N_P = 1024")
    # a third, larger N_L without gains: the table keeps the N_L the verdict reads, between
    # the smallest and the largest
    third = pd.concat([rows, rows[rows["n_labelled"] == 8].assign(n_labelled=128)])
    table = pool_table(seed_view(third.reset_index(drop=True)))
    assert sorted(set(table["N_L"])) == [8, 64, 128]
    at_64 = table[
        (table["N_L"] == 64) & (table["ρ"] == "1") & (table["rung"] == "kernel ridge V→T")
    ]
    assert "3/3 ↑" in at_64["N_P = 1024"].item()
    # no oracle gain at any N_L: the fewest labels, and the verdict says it cannot show a gain
    void = seed_view(_ladder_summary({(1.0, "kernel_ridge", 1024): True}, pools))
    assert reading_n_labelled(void, "hardness", 1.0) == 8
    assert pool_verdict(void)[0].endswith("so the curve cannot show what a generator would add.")


def _control_view(above: dict[tuple, bool], pools: tuple[int, ...]) -> pd.DataFrame:
    """The positive control's `seed_view`: the largest rho's rows of `_ladder_summary`
    without the diffusion generator's rungs."""
    from tacgen_lib.report.regime import seed_view

    rows = _ladder_summary(above, pools)
    keep = (rows["rho"] == 1.0) & ~rows["arm"].isin(["gen_mean", "v_tgen"])
    return seed_view(rows[keep].reset_index(drop=True))


def test_the_pool_page_shows_its_positive_control_apart_from_the_rho_grid():
    """The control's sentence names where its learnt rungs first gain (or that the control
    fails); its rows in the table say their touch; its panel is the figure's third column."""
    import matplotlib

    matplotlib.use("Agg")
    from tacgen_lib.report.regime import pool_curve_figure, pool_table, seed_view
    from tacgen_lib.report.regime_pool import pool_verdict
    from tacgen_lib.report.write import figure_problems

    pools = (256, 1024, 4096)
    view = seed_view(_ladder_summary({(1.0, "look_oracle"): True}, pools))
    gaining = _control_view({(1.0, "look_oracle"): True, (1.0, "knn", 4096): True}, pools)
    curve, said, flat = pool_verdict(view, gaining, 0.5)
    assert "no learnt rung" in curve  # the real touch's curve is read as before
    assert said.startswith("Positive control of the curve (hardness, ρ = 1, N_L = 8, touch = ")
    assert "at SNR 0.5" in said and "first gains over nonlinear V" in said
    assert "at N_P = 4096 (A1 kNN in V: " in said and "kNN in V +0.000 → +0.100" in said
    assert "The control fails" not in said and flat.startswith("Pool-size control")
    (_, failed, _) = pool_verdict(view, _control_view({(1.0, "look_oracle"): True}, pools), 0.5)
    assert failed.endswith("does not say the real touch lacks it.")
    # where even the oracle gains at no pool size on the control's touch, the probe lacks power
    (_, powerless, _) = pool_verdict(view, _control_view({}, pools), 0.5)
    assert powerless.endswith("so the control says nothing of the rungs at this N_L.")
    # every target gets its own control sentence
    both = seed_view(
        pd.concat(
            [
                _ladder_summary({(1.0, "look_oracle"): True}, pools),
                _ladder_summary({(1.0, "look_oracle"): True}, pools).assign(target="density"),
            ]
        )
    )
    twice = pd.concat([gaining, gaining.assign(target="density")], ignore_index=True)
    notes = pool_verdict(both, twice, 0.5)
    assert [n.split(" (")[0] for n in notes] == [
        "Pool size",
        "Positive control of the curve",
        "Pool-size control",
    ] * 2
    table = pool_table(view, gaining)
    control_rows = table[table["touch"] == "look + noise (control)"]
    assert len(control_rows) == 2 * 4  # N_L x (the look oracle and three learnt rungs)
    assert set(table.loc[table["touch"] == "real", "ρ"]) == {"0", "1"}
    fig = pool_curve_figure(view, gaining)
    assert len(fig.axes) == 3 and figure_problems(fig) == []
    assert fig.axes[2].get_title().startswith("hardness, positive control\nlook + noise, ρ = 1")


def test_the_findings_page_gives_the_pool_verdict_and_its_decisions_where_two_pools_ran():
    from tacgen_lib.report.findings import regime_findings

    one = pd.concat([_regime_rows(0.0), _regime_rows(1.0)], ignore_index=True)
    found, decided = regime_findings(one)
    assert not [d for d in decided if "pool_first_gain" in d["decision_id"]]
    assert not found["verdict"].str.contains("Pool size", regex=False).any()
    # the same rows again as a second pool size (the pool's rows do not enter the summary)
    two = pd.concat([one, one.assign(n_pool=400)], ignore_index=True)
    found, decided = regime_findings(two)
    pools = {
        d["decision_id"]: d["decision"] for d in decided if "pool_first_gain" in d["decision_id"]
    }
    assert set(pools) == {
        f"regime|{t}|pool_first_gain_{k}"
        for t in ("hardness", "log_mass")
        for k in ("learnt", "diffusion")
    }
    assert all(v == "none up to 400" or v.startswith("N_P = 100 (") for v in pools.values())
    # the positive control's rows (a second copy of the largest rho's) add its decision
    control = two[(two["rho"] == 1.0) & ~two["arm"].isin(["gen_mean", "v_tgen"])]
    found, decided = regime_findings(two, control=control, snr=1.0)
    ids = {d["decision_id"] for d in decided}
    assert {f"regime|{t}|pool_first_gain_control_learnt" for t in ("hardness", "log_mass")} <= ids
    assert found["verdict"].str.contains("Positive control of the curve", regex=False).all()
    assert (
        found["verdict"]
        .str.contains("Pool size (hardness, ρ = 1, N_L = 6, N_P 100–400)", regex=False)
        .any()
    )
