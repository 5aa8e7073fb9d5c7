"""The generator ladder's rungs (tacgen_lib.generate.ladder) and what a frame shows
(tacgen_lib.corpus.looks): the look oracle against a float64 group mean, a look with one pool
row, a look absent from the pool, kNN against scikit-learn's KNeighborsRegressor, k larger than
the pool, and the look keys read back from the captions' vocabulary."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.neighbors import KNeighborsRegressor
from sklearn.preprocessing import StandardScaler

from tacgen_lib.corpus.looks import look_keys, visible_factors
from tacgen_lib.generate.ladder import knn_generate, ladder_rungs, look_oracle
from tacgen_lib.generate.regime_sets import RegimeSettings

#: the ladder's settings in these tests: every look averaged, a small kNN grid
_REGIME = RegimeSettings(look_min_rows=1, knn_ks=(1, 2, 4))


def _world(n: int, d: int = 5, seed: int = 0):
    rng = np.random.default_rng(seed)
    ids = [f"s-{i:04d}" for i in range(n)]
    t = {i: rng.normal(size=d) for i in ids}
    v = {i: rng.normal(size=3) for i in ids}
    return ids, v, t, rng


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 60), k_looks=st.integers(1, 8), seed=st.integers(0, 10_000))
def test_look_oracle_is_the_float64_mean_of_the_pool_rows_of_each_look(n, k_looks, seed):
    ids, _, t, rng = _world(n, seed=seed)
    looks = pd.Series({i: f"look{int(rng.integers(k_looks))}" for i in ids})
    pool, rows = ids[: max(1, n // 2)], ids
    got = look_oracle(t, looks, pool, rows, min_rows=1)
    for i in rows:
        same = [j for j in pool if looks[j] == looks[i]]
        want = (
            np.mean([t[j] for j in same], axis=0) if same else np.mean([t[j] for j in pool], axis=0)
        )
        np.testing.assert_allclose(got.t_gen[i], want, rtol=1e-12, atol=1e-12)
    absent = sum(1 for i in rows if looks[i] not in set(looks[pool]))
    assert got.n_fallback == absent and got.n_looks == looks[pool].nunique()


def test_a_look_with_one_pool_row_gives_that_rows_touch_exactly():
    ids, _, t, _ = _world(6)
    looks = {i: "a" for i in ids} | {ids[0]: "single", ids[5]: "single"}
    got = look_oracle(t, looks, ids[:4], [ids[5]], min_rows=1)
    np.testing.assert_array_equal(got.t_gen[ids[5]], t[ids[0]])
    assert got.n_fallback == 0


def test_a_look_absent_from_the_pool_falls_back_to_the_pool_mean_and_is_counted():
    ids, _, t, _ = _world(8)
    looks = {i: "a" for i in ids} | {ids[7]: "never seen"}
    got = look_oracle(t, looks, ids[:5], ids[5:], min_rows=1)
    np.testing.assert_allclose(got.t_gen[ids[7]], np.mean([t[i] for i in ids[:5]], axis=0))
    assert got.n_fallback == 1


def test_a_rare_look_backs_off_to_a_coarser_one_before_the_pool_mean():
    ids, _, t, _ = _world(12)
    pool, rows = ids[:9], ids[9:]
    # finest: pool looks "a" (x2) and "b" (x7); coarse: "a" and "b" are both "ab"
    fine = {i: "a" for i in ids[:2]} | {i: "b" for i in ids[2:9]}
    fine |= {ids[9]: "a", ids[10]: "b", ids[11]: "z"}
    coarse = {i: "ab" for i in ids[:9]} | {ids[9]: "ab", ids[10]: "ab", ids[11]: "zz"}
    got = look_oracle(t, [fine, coarse], pool, rows, min_rows=3)
    pool_mean = np.mean([t[i] for i in pool], axis=0)
    # "a": 2 < 3 pool rows, so the coarse "ab": all 9 pool rows
    np.testing.assert_allclose(got.t_gen[ids[9]], pool_mean, rtol=1e-12)
    np.testing.assert_allclose(
        got.t_gen[ids[10]], np.mean([t[i] for i in ids[2:9]], axis=0), rtol=1e-12
    )
    np.testing.assert_allclose(got.t_gen[ids[11]], pool_mean, rtol=1e-12)
    # one row at the finest level, one at the coarse ("ab" holds all 9), one on the pool mean
    assert got.levels == (1, 1, 1) and got.n_fallback == 1 and got.n_looks == 2
    with pytest.raises(ValueError, match="min_rows"):
        look_oracle(t, fine, pool, rows, min_rows=0)


def test_look_oracle_refuses_an_empty_pool_and_a_row_without_a_look():
    ids, _, t, _ = _world(4)
    with pytest.raises(ValueError, match="pool is empty"):
        look_oracle(t, {i: "a" for i in ids}, [], ids, min_rows=1)
    with pytest.raises(ValueError, match="'s-0003' has no look"):
        look_oracle(t, {i: "a" for i in ids[:3]}, ids[:2], ids, min_rows=1)


def test_knn_equals_scikit_learns_regressor_at_the_k_cv_chose():
    ids, v, t, _ = _world(80)
    pool, rows = ids[:60], ids[60:]
    got = knn_generate(v, t, pool, rows, ks=(1, 3, 9), seed=0)
    assert got.k in (1, 3, 9) and np.isfinite(got.cv_mse)
    x = np.stack([v[i] for i in pool])
    scaler = StandardScaler().fit(x)
    ref = KNeighborsRegressor(n_neighbors=got.k).fit(
        scaler.transform(x), np.stack([t[i] for i in pool])
    )
    want = ref.predict(scaler.transform(np.stack([v[i] for i in rows])))
    np.testing.assert_allclose(np.stack([got.t_gen[i] for i in rows]), want, rtol=1e-12)


def test_k_larger_than_the_pool_gives_every_row_the_pool_mean():
    ids, v, t, _ = _world(12)
    pool, rows = ids[:4], ids[4:]
    got = knn_generate(v, t, pool, rows, ks=(500,), seed=0)
    assert got.k == 4 and np.isnan(got.cv_mse)  # no k fits a CV training fold: capped, no CV
    mean = np.mean([t[i] for i in pool], axis=0)
    for i in rows:
        np.testing.assert_allclose(got.t_gen[i], mean, rtol=1e-12)


def test_ladder_rungs_learn_from_the_pool_only():
    """Changing the touch of a row outside the pool changes no rung's T_gen."""
    ids, v, t, _ = _world(40)
    looks = {i: f"l{k % 3}" for k, i in enumerate(ids)}
    pool, rows = ids[:25], ids[25:]
    gen_mean = {i: np.zeros(5) for i in rows}
    a = ladder_rungs(v, t, looks, pool, rows, gen_mean, regime=_REGIME, seed=0)
    t2 = dict(t) | {i: t[i] + 100.0 for i in rows}
    b = ladder_rungs(v, t2, looks, pool, rows, gen_mean, regime=_REGIME, seed=0)
    for rung in ("look_oracle", "knn", "ridge", "kernel_ridge", "gen_mean"):
        for i in rows:
            np.testing.assert_array_equal(a.t_gen[rung][i], b.t_gen[rung][i])
    assert "look oracle: 3 looks" in a.describe()
    assert "kernel ridge: gamma = " in a.describe() and "exact kernel" in a.describe()


def test_ladder_rungs_refuse_a_row_asked_for_that_is_in_the_pool():
    ids, v, t, _ = _world(30)
    looks = {i: "a" for i in ids}
    gen_mean = {i: np.zeros(5) for i in ids}
    with pytest.raises(ValueError, match="'s-0019' is in the pool"):
        ladder_rungs(v, t, looks, ids[:20], ids[19:], gen_mean, regime=_REGIME, seed=0)


def test_visible_factors_read_the_captions_vocabulary_and_name_a_bad_sample():
    manifest = pd.DataFrame(
        {
            "sample_id": ["n-0", "n-1"],
            "adjectives": [
                ["small", "red", "striped", "hard", "light"],
                ["large", "black", "plain", "soft", "heavy"],
            ],
            "shape": ["cube", "sphere"],
            "appearance_id": [2, 1],
        }
    )
    f = visible_factors(manifest, appearance_class=True)
    assert f.loc["n-0"].to_dict() == {
        "colour": "red",
        "texture": "striped",
        "shape": "cube",
        "size": "small",
        "appearance": "2",
    }
    assert "appearance" not in visible_factors(manifest)  # an object index elsewhere
    assert look_keys(f).to_dict() == {
        "n-0": "red|striped|cube|small",
        "n-1": "black|plain|sphere|large",
    }
    bad = manifest.assign(adjectives=[["small", "red", "hard"], ["large", "black", "plain"]])
    with pytest.raises(ValueError, match="sample_id 'n-0'.*texture"):
        visible_factors(bad)
