"""The ladder's kernel ridge rung (tacgen_lib.generate.kernel_ridge_generator): its T_gen is
scikit-learn's KernelRidge on the pool's standardised V and centred T at the gamma and lambda
CV chose, that choice is brute-force K-fold CV of the mean R² over T's dimensions, CV picks
the right gamma where T is a known nonlinear function of V, the Nystroem path agrees with the
exact kernel where both fit, and a row asked for that is in the pool is refused."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from sklearn.kernel_ridge import KernelRidge
from sklearn.metrics import r2_score
from sklearn.model_selection import KFold
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from tacgen_lib.generate.baselines import median_sq_distance
from tacgen_lib.generate.kernel_ridge_generator import kernel_ridge_generate
from tacgen_lib.generate.regime_sets import RegimeSettings

#: a small grid for the tests (the config's is `RegimeSettings().kernel_ridge_*`)
_REGIME = RegimeSettings(kernel_ridge_gammas=(0.1, 1.0, 10.0), kernel_ridge_lambdas=(0.01, 1.0))


def _world(n: int, *, d_v: int = 4, d_t: int = 3, noise: float = 0.1, freq: float = 1.0):
    """V standard normal; T a smooth nonlinear function of V (of scale ~ 10) plus noise."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(n, d_v))
    w = rng.normal(size=(d_v, d_t)) / np.sqrt(d_v)
    t = 10.0 * np.sin(freq * v @ w) + 5.0 + noise * rng.normal(size=(n, d_t))
    ids = [f"s-{i:04d}" for i in range(n)]
    return ids, dict(zip(ids, v, strict=True)), dict(zip(ids, t, strict=True))


def _stack(m, ids):
    return np.stack([m[i] for i in ids])


def _reference(v_pool, t_pool, v_rows, multiple: float, lam: float) -> np.ndarray:
    """KernelRidge on V standardised by the pool, T centred by the pool's mean (float64)."""
    scaler = StandardScaler().fit(v_pool)
    z = scaler.transform(v_pool)
    gamma = multiple / median_sq_distance(z)
    mean = t_pool.mean(axis=0)
    model = KernelRidge(alpha=lam, kernel="rbf", gamma=gamma).fit(z, t_pool - mean)
    return model.predict(scaler.transform(v_rows)) + mean


def test_t_gen_is_scikit_learns_kernel_ridge_at_the_cv_choice_and_the_choice_is_brute_force_cv():
    ids, v, t = _world(140)
    pool, rows = ids[:100], ids[100:]
    with threadpool_limits(1):
        got = kernel_ridge_generate(v, t, pool, rows, regime=_REGIME, seed=3)
    v_pool, t_pool = _stack(v, pool), _stack(t, pool)
    want = _reference(v_pool, t_pool, _stack(v, rows), got.gamma_multiple, got.lam)
    np.testing.assert_allclose(_stack(got.t_gen, rows), want, rtol=1e-8, atol=1e-8)
    assert got.nystroem_rank == 0 and "exact kernel" in got.describe()
    # the choice: 5-fold CV (seeded shuffle), mean over T's dimensions of the held-out R²,
    # V standardised and T centred on each fold's training rows, gamma's scale the pool's
    scores = {}
    for mult in _REGIME.kernel_ridge_gammas:
        for lam in _REGIME.kernel_ridge_lambdas:
            r2 = []
            for tr, te in KFold(5, shuffle=True, random_state=3).split(v_pool):
                scaler = StandardScaler().fit(v_pool[tr])
                gamma = mult / median_sq_distance(StandardScaler().fit_transform(v_pool))
                mean = t_pool[tr].mean(axis=0)
                model = KernelRidge(alpha=lam, kernel="rbf", gamma=gamma)
                model.fit(scaler.transform(v_pool[tr]), t_pool[tr] - mean)
                pred = model.predict(scaler.transform(v_pool[te])) + mean
                r2.append(r2_score(t_pool[te], pred))
            scores[(mult, lam)] = float(np.mean(r2))
    best = max(scores, key=scores.get)
    assert (got.gamma_multiple, got.lam) == best
    assert got.cv_r2 == pytest.approx(scores[best], rel=1e-9)


def test_cv_picks_the_gamma_of_the_function_t_is_made_of():
    """T = 10 sin(f V w) + noise on 2-D V: the faster T varies (the larger f), the narrower the
    kernel (the larger the gamma multiple) CV chooses; T is known to be smooth at every f, so
    the chosen fit explains most of its variance where the noise is small."""
    grid = replace(
        _REGIME, kernel_ridge_gammas=(0.01, 0.1, 1.0, 10.0), kernel_ridge_lambdas=(0.01, 0.1, 1.0)
    )
    chosen = {}
    with threadpool_limits(1):
        for freq, noise in ((3.0, 0.5), (1.0, 0.5), (0.2, 3.0)):
            ids, v, t = _world(300, d_v=2, d_t=2, noise=noise, freq=freq)
            chosen[freq] = kernel_ridge_generate(v, t, ids[:250], ids[250:], regime=grid, seed=0)
    assert chosen[3.0].gamma_multiple == 10.0 and chosen[3.0].cv_r2 > 0.8
    assert chosen[1.0].gamma_multiple == 1.0 and chosen[1.0].cv_r2 > 0.9
    assert chosen[0.2].gamma_multiple <= 0.1


def test_the_nystroem_path_agrees_with_the_exact_kernel_where_both_fit():
    """Above ``nystroem_above`` rows the rung is ridge on Nystroem features: on a pool of 600
    rows with rank 300 its choice is the exact kernel's, its test R² within 0.02 of it and
    its predictions correlated above 0.99 with the exact kernel's."""
    ids, v, t = _world(800, d_v=6, d_t=4, noise=1.0)
    pool, rows = ids[:600], ids[600:]
    with threadpool_limits(1):
        exact = kernel_ridge_generate(v, t, pool, rows, regime=_REGIME, seed=0)
        nys = kernel_ridge_generate(
            v, t, pool, rows, regime=replace(_REGIME, nystroem_above=500, nystroem_rank=300), seed=0
        )
    assert exact.nystroem_rank == 0 and nys.nystroem_rank == 300
    assert "Nystroem rank 300" in nys.describe()
    assert (nys.gamma_multiple, nys.lam) == (exact.gamma_multiple, exact.lam)
    y, pe, pn = _stack(t, rows), _stack(exact.t_gen, rows), _stack(nys.t_gen, rows)
    assert abs(r2_score(y, pe) - r2_score(y, pn)) < 0.02
    for j in range(y.shape[1]):
        assert np.corrcoef(pe[:, j], pn[:, j])[0, 1] > 0.99


def test_a_row_asked_for_that_is_in_the_pool_is_refused_and_the_rung_reads_the_pool_only():
    ids, v, t = _world(60)
    pool, rows = ids[:40], ids[40:]
    with pytest.raises(ValueError, match="'s-0039' is in the pool"):
        kernel_ridge_generate(v, t, pool, ids[39:], regime=_REGIME, seed=0)
    with pytest.raises(ValueError, match="has no vector"):
        kernel_ridge_generate(v, {i: t[i] for i in pool[1:]}, pool, rows, regime=_REGIME, seed=0)
    a = kernel_ridge_generate(v, t, pool, rows, regime=_REGIME, seed=0)
    # the touch of the rows asked for is never read
    b = kernel_ridge_generate(v, {i: t[i] for i in pool}, pool, rows, regime=_REGIME, seed=0)
    np.testing.assert_array_equal(_stack(a.t_gen, rows), _stack(b.t_gen, rows))


def test_a_pool_smaller_than_the_folds_takes_the_grids_middle_without_cv():
    ids, v, t = _world(10)
    got = kernel_ridge_generate(v, t, ids[:4], ids[4:], regime=_REGIME, seed=0)
    assert (got.gamma_multiple, got.lam) == (1.0, 0.01) and np.isnan(got.cv_r2)
