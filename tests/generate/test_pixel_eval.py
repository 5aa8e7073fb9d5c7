"""Frames, reconstruction, calibration, the scale curve and the arm evaluation of the pixel
generators (tacgen_lib.generate.pixel.{frames,quality,curve,utility}), against library and
float64 references."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from generate_worlds import toy_specs, toy_world, train_ids
from scipy import ndimage
from skimage.metrics import mean_squared_error, structural_similarity

from tacgen_lib.generate.baselines import fit_baselines
from tacgen_lib.generate.evaluate import evaluate_generator
from tacgen_lib.generate.pixel import curve, frames, quality, utility
from tacgen_lib.io.images import encode_png


def _frames(n=6, size=(12, 16), seed=0):
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, (n, *size, 3), dtype=np.uint8)


def test_units_are_exact_and_the_background_is_zero():
    """clip128 background 128 -> exactly 0; tactile units -> uint8 is the exact inverse for
    every uint8 value; RGB lies in [-1, 1]."""
    x = np.arange(256, dtype=np.uint8).reshape(1, 16, 16, 1).repeat(3, axis=-1)
    u = frames.tactile_units(x)
    assert u.shape == (1, 3, 16, 16) and u.dtype == np.float32
    assert u.min() == -1.0 and u.max() == np.float32(127 / 128)
    assert (u[x.transpose(0, 3, 1, 2) == 128] == 0).all()
    back, clipped = frames.to_uint8_tactile(u)
    np.testing.assert_array_equal(back, x)
    assert clipped == 0.0
    r = frames.rgb_units(x)
    assert r.min() == -1.0 and r.max() == 1.0


def test_the_only_clipping_is_counted_and_non_finite_frames_are_refused():
    u = np.zeros((2, 3, 4, 4), np.float32)
    u[0, 0, 0, :2] = [1.5, -1.2]  # two of 96 values leave 0..255
    out, clipped = frames.to_uint8_tactile(u)
    assert clipped == pytest.approx(2 / 96)
    assert out[0, 0, 0, 0] == 255 and out[0, 0, 1, 0] == 0
    u[1, 1, 1, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        frames.to_uint8_tactile(u)


def test_paired_frames_name_the_odd_sample():
    """Rows in another order, and a wrongly sized frame, stop with the edge and sample_id."""
    imgs = _frames(3, (12, 16))
    rgb = pd.DataFrame({"sample_id": ["a", "b", "c"], "rgb": [encode_png(i) for i in imgs]})
    tac = pd.DataFrame(
        {"sample_id": ["a", "b", "c"], "tactile_proc": [encode_png(i) for i in imgs]}
    )
    r, t = frames.paired_frames(rgb, tac, (6, 8), rgb_where="s.parquet", tactile_where="t.parquet")
    assert r.shape == t.shape == (3, 6, 8, 3)
    with pytest.raises(ValueError, match=r"first sample_id 'a'"):
        frames.paired_frames(
            rgb, tac.iloc[::-1], (6, 8), rgb_where="s.parquet", tactile_where="t.parquet"
        )
    odd = tac.copy()
    odd.loc[1, "tactile_proc"] = encode_png(_frames(1, (10, 16))[0])
    with pytest.raises(ValueError, match=r"t\.parquet: sample_id 'b' has a \(10, 16, 3\)"):
        frames.paired_frames(rgb, odd, (6, 8), rgb_where="s.parquet", tactile_where="t.parquet")
    bad = tac.copy()
    bad.loc[2, "tactile_proc"] = b"not a png"
    with pytest.raises(ValueError, match=r"t\.parquet: sample_id 'c'"):
        frames.paired_frames(rgb, bad, (6, 8), rgb_where="s.parquet", tactile_where="t.parquet")


def test_reconstruction_measures_equal_the_libraries():
    """pixel-L2 = sqrt(skimage MSE) on [0, 1] frames; SSIM = skimage's per frame; the Laplacian
    energy = the 4-neighbour stencil on mirror-padded frames, float64."""
    a, b = _frames(4, seed=1), _frames(4, seed=2)
    l2 = quality.pixel_l2(a, b)
    for i in range(4):
        assert l2[i] == pytest.approx(np.sqrt(mean_squared_error(a[i] / 255.0, b[i] / 255.0)))
        assert quality.ssim(a, b)[i] == pytest.approx(
            structural_similarity(a[i], b[i], channel_axis=-1, data_range=255)
        )
    assert quality.ssim(a, a) == pytest.approx(np.ones(4))
    u = frames.tactile_units(a).astype(np.float64)
    pad = np.pad(u.reshape(-1, 12, 16), ((0, 0), (1, 1), (1, 1)), mode="reflect")
    lap = (
        pad[:, :-2, 1:-1]
        + pad[:, 2:, 1:-1]
        + pad[:, 1:-1, :-2]
        + pad[:, 1:-1, 2:]
        - 4 * pad[:, 1:-1, 1:-1]
    )
    ref = np.mean(lap**2)
    assert quality.highpass_energy(u) == pytest.approx(ref, rel=1e-6)


def test_the_gain_matches_contrast_on_train_rows_and_leaves_blank_frames_alone():
    real = frames.tactile_units(_frames(5, seed=3))
    gen = np.float32(0.37) * real
    g = quality.fit_gain(gen, real)
    assert g == pytest.approx(1 / 0.37, rel=1e-6)
    assert quality.std_ratio(np.float32(g) * gen, real) == pytest.approx(1.0, rel=1e-6)
    # an all-background generator (zero residual) has no contrast to scale
    assert quality.fit_gain(np.zeros_like(gen), real) == 1.0
    # texture ratio: a blurred copy has less high-pass energy than the frame
    blurred = ndimage.uniform_filter(real, size=(1, 1, 3, 3))
    assert quality.highpass_ratio(blurred, real) < 0.5


def test_mean_interval_is_the_percentile_bootstrap_of_the_mean():
    v = np.random.default_rng(0).normal(size=50)
    mean, lo, hi = quality.mean_interval(v, n_resamples=2000, seed=3)
    rng = np.random.default_rng(3)
    means = v[rng.integers(0, 50, (2000, 50))].mean(axis=1)
    assert mean == pytest.approx(v.mean())
    assert (lo, hi) == pytest.approx(tuple(np.quantile(means, [0.025, 0.975])))
    assert quality.mean_interval(np.ones(7), n_resamples=100, seed=0) == (1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="finite"):
        quality.mean_interval(np.array([1.0, np.nan]), n_resamples=10, seed=0)


def test_replaced_rows_and_mixed_tactile():
    ids = [f"s{i}" for i in range(10)]
    assert curve.replaced_rows(ids, 0.0, 1) == []
    assert curve.replaced_rows(ids, 1.0, 1) == sorted(ids)
    half = curve.replaced_rows(ids, 0.5, 1)
    assert len(half) == 5 and half == curve.replaced_rows(ids, 0.5, 1)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        curve.replaced_rows(ids, 1.5, 1)
    real = {i: np.array([k, 0.0]) for k, i in enumerate(ids)}
    gen = {i: np.array([k, 1.0]) for k, i in enumerate(ids)}
    mixed = curve.mixed_tactile(real, gen, half, pairing="generated", seed=0)
    assert all((mixed[i] == gen[i]).all() == (i in half) for i in ids)
    shuf = curve.mixed_tactile(real, gen, ids, pairing="shuffled", seed=0)
    # every row gets another row's generated vector: the marginal kept, the pairing broken
    assert all(shuf[i][1] == 1.0 and shuf[i][0] != real[i][0] for i in ids)
    assert sorted(v[0] for v in shuf.values()) == list(range(10))
    with pytest.raises(ValueError, match="sample_id 's9'"):
        curve.mixed_tactile(real, {i: gen[i] for i in ids[:-1]}, [], pairing="generated", seed=0)


def _identity_heads(v, t, train_idx, val_idx):
    """Stand-in heads for curve_point: remember what they were trained on."""
    return {"t": t.copy(), "train": np.asarray(train_idx), "val": np.asarray(val_idx)}


def _identity_project(heads, v, t):
    return v.astype(np.float32), t.astype(np.float32)


def test_curve_point_trains_on_generated_rows_and_probes_real_touch():
    """The heads see generated tactile on round(p n) rows of train and of val; the probes
    always see REAL touch, so with identity heads every p gives the real-touch Δ."""
    ids, vision, t_real, specs = toy_specs()
    splits = toy_world()[4]
    head_ids = {
        s: sorted(splits.loc[splits["split"] == s, "sample_id"]) for s in ("train", "val", "test")
    }
    t_gen = {i: np.full_like(x, 7.0) for i, x in t_real.items()}
    seen = {}

    def heads(v, t, tr, va):
        seen["t"] = t
        return _identity_heads(v, t, tr, va)

    rows = {}
    point = dict(corpus="toy", generator="pix2pix", seed=0, pairing="generated")
    data = dict(vision=vision, t_real=t_real, t_gen=t_gen, head_ids=head_ids)
    for p in (0.0, 0.5, 1.0):  # the same point but for the fraction replaced
        rows[p] = curve.curve_point(
            specs, fraction=p, **point, **data, fit_heads=heads, project=_identity_project
        )
        n_fit = len(head_ids["train"]) + len(head_ids["val"])
        n_gen = int(np.sum(np.all(seen["t"] == 7.0, axis=1)))
        assert n_gen == rows[p]["n_replaced"].iloc[0]
        assert n_gen == pytest.approx(p * n_fit, abs=1)
    assert list(rows[1.0].columns) == list(curve.CURVE_COLUMNS)
    for col in ("v_score", "score", "delta", "ci_low", "ci_high"):
        np.testing.assert_array_equal(rows[0.0][col], rows[1.0][col])
    assert rows[0.0].set_index("target").loc["force_p50", "ci_low"] > 0  # touch sees hidden


def test_arm_names_round_trip():
    assert utility.ddpm_arm(1, 10) == "ddpm_w1_s10"
    assert utility.ddpm_arm(1.5, "25") == "ddpm_w1.5_s25"
    assert utility.arm_generator("ddpm_w1.5_s25_cal") == ("ddpm", 1.5, 25, True)
    g, w, s, cal = utility.arm_generator("pix2pix")
    assert (g, s, cal) == ("pix2pix", 0, False) and np.isnan(w)
    with pytest.raises(ValueError, match="unknown pixel generator arm"):
        utility.arm_generator("gan")


def test_evaluate_arms_is_the_latent_generators_evaluation_relabelled():
    """Every number of an arm's rows equals evaluate_generator's for the same vectors; only the
    labels change (arm, generator, guidance, steps, calibrated, row_id)."""
    ids, vision, t_real, specs = toy_specs()
    specs = [
        dataclasses.replace(s, settings=dataclasses.replace(s.settings, bootstrap=200))
        for s in specs
    ]
    splits = toy_world()[4]
    rng = np.random.default_rng(5)
    arm_vectors = {
        "pix2pix": {i: x + rng.normal(size=x.shape).astype(np.float32) for i, x in t_real.items()},
        "ddpm_w1_s10_cal": {
            i: rng.normal(size=x.shape).astype(np.float32) for i, x in t_real.items()
        },
    }
    baselines = {s.name: fit_baselines(s, vision, t_real, gammas=(1.0,)) for s in specs}
    kw = dict(
        corpus="toy",
        seed=0,
        vision=vision,
        t_real=t_real,
        baselines=baselines,
        permutations=20,
        generator_train_ids=train_ids(splits),
    )
    rows, perms = utility.evaluate_arms(specs, arms=arm_vectors, reference="pix2pix", **kw)
    ref, _ = evaluate_generator(
        specs,
        t_gen={(a, "0", "0"): v for a, v in arm_vectors.items()},
        reference=("pix2pix", "0", "0"),
        **kw,
    )
    assert rows["row_id"].is_unique and perms["row_id"].is_unique
    cal = rows[rows["arm"] == "ddpm_w1_s10_cal"]
    assert set(cal["generator"]) == {"ddpm"} and cal["calibrated"].all()
    assert set(cal["guidance"]) == {1.0} and set(cal["steps"]) == {10}
    for col in ("score", "delta", "ci_low", "ci_high", "cos_matched"):
        np.testing.assert_array_equal(rows[col].to_numpy(), ref[col].to_numpy())
    with pytest.raises(ValueError, match="reference arm 'gan'"):
        utility.evaluate_arms(specs, arms=arm_vectors, reference="gan", **kw)
