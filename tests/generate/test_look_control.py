"""The positive control's touch (`tacgen_lib.generate.look_control`): the look's mean real
touch over the reference rows plus noise at the stated signal-to-noise ratio."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tacgen_lib.generate.look_control import look_control_touch


def _corpus(n: int = 3000, d: int = 6, looks: int = 5, seed: int = 0):
    rng = np.random.default_rng(seed)
    ids = [f"s{i:05d}" for i in range(n)]
    look = pd.Series([f"look{k}" for k in rng.integers(looks, size=n)], index=ids)
    centres = {f"look{k}": rng.normal(size=d) for k in range(looks)}
    t_real = {i: centres[look[i]] + rng.normal(size=d) for i in ids}
    reference = ids[: n * 4 // 5]  # the non-test rows
    return ids, look, t_real, reference


def _means_by_loop(t_real, look, reference) -> dict[str, np.ndarray]:
    """The float64 look means, one look at a time (the reference of the vectorised means)."""
    out = {}
    for key in sorted(set(look.loc[reference])):
        members = [i for i in reference if look[i] == key]
        out[key] = np.sum([np.asarray(t_real[i], np.float64) for i in members], axis=0) / len(
            members
        )
    return out


def test_the_signal_is_the_reference_rows_look_mean_and_the_noise_has_the_stated_snr():
    ids, look, t_real, reference = _corpus()
    built = look_control_touch(t_real, look, reference, ids, snr=0.5, seed=3)
    means = _means_by_loop(t_real, look, reference)
    mu = np.stack([means[look[i]] for i in ids])
    t = np.stack([built.t_control[i] for i in ids])
    # the signal's variance per dimension over the reference rows, as documented
    mu_ref = np.stack([means[look[i]] for i in reference])
    np.testing.assert_allclose(built.signal_variance, mu_ref.var(axis=0).mean(), rtol=1e-12)
    assert built.sigma == pytest.approx(np.sqrt(built.signal_variance / 0.5), rel=1e-12)
    noise = t - mu
    # 3000 x 6 standard normal draws scaled by sigma: their variance within 5 % of sigma^2
    assert noise.var() == pytest.approx(built.sigma**2, rel=0.05)
    assert abs(noise.mean()) < 0.05 * built.sigma
    assert built.n_looks == 5 and built.snr == 0.5
    # a huge SNR leaves the look means alone (within float64 rounding of the sum)
    clean = look_control_touch(t_real, look, reference, ids, snr=1e24, seed=3)
    np.testing.assert_allclose(np.stack([clean.t_control[i] for i in ids]), mu, rtol=0, atol=1e-9)


def test_held_out_touch_never_enters_the_control():
    """A test row's real touch (not a reference row) changes nothing: its control touch is
    its look's mean over the reference rows plus its own noise."""
    ids, look, t_real, reference = _corpus(n=500)
    held_out = ids[len(reference) :]
    changed = {**t_real, **{i: t_real[i] + 100.0 for i in held_out}}
    a = look_control_touch(t_real, look, reference, ids, snr=1.0, seed=0)
    b = look_control_touch(changed, look, reference, ids, snr=1.0, seed=0)
    for i in ids:
        np.testing.assert_array_equal(a.t_control[i], b.t_control[i])


def test_the_noise_is_seeded_and_does_not_follow_the_order_rows_are_asked_in():
    ids, look, t_real, reference = _corpus(n=400)
    a = look_control_touch(t_real, look, reference, ids, snr=1.0, seed=7)
    b = look_control_touch(t_real, look, reference, ids[::-1], snr=1.0, seed=7)
    c = look_control_touch(t_real, look, reference, ids, snr=1.0, seed=8)
    for i in ids:
        np.testing.assert_array_equal(a.t_control[i], b.t_control[i])
    assert not np.allclose(a.t_control[ids[0]], c.t_control[ids[0]])
    assert "SNR 1" in a.describe() and "5 looks" in a.describe()


def test_a_look_no_reference_row_shows_gets_the_reference_mean():
    ids, look, t_real, reference = _corpus(n=300)
    rare = look.copy()
    rare[ids[-1]] = "unseen"  # a held-out row's look that no reference row shows
    built = look_control_touch(t_real, rare, reference, ids, snr=1e24, seed=0)
    overall = np.mean([t_real[i] for i in reference], axis=0)
    np.testing.assert_allclose(built.t_control[ids[-1]], overall, rtol=0, atol=1e-9)
    assert built.n_unseen == 1 and "1 rows of a look no reference row shows" in built.describe()
    assert look_control_touch(t_real, look, reference, ids, snr=1.0, seed=0).n_unseen == 0


def test_bad_inputs_are_refused_with_what_is_wrong():
    ids, look, t_real, reference = _corpus(n=200)
    with pytest.raises(ValueError, match="snr must be > 0"):
        look_control_touch(t_real, look, reference, ids, snr=0.0, seed=0)
    with pytest.raises(ValueError, match="no reference rows"):
        look_control_touch(t_real, look, [], ids, snr=1.0, seed=0)
    with pytest.raises(ValueError, match="sample_id 'ghost' has no look"):
        look_control_touch(t_real, look, reference, [*ids, "ghost"], snr=1.0, seed=0)
    one_look = pd.Series("same", index=ids)
    with pytest.raises(ValueError, match="show one look .'same'."):
        look_control_touch(t_real, one_look, reference, ids, snr=1.0, seed=0)
    flat = {i: np.ones(6) for i in ids}  # touch that does not differ between looks
    with pytest.raises(ValueError, match="look means are all equal"):
        look_control_touch(flat, look, reference, ids, snr=1.0, seed=0)
