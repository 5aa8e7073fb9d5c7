"""The pixel V -> T generators (pix2pix, pixel DDPM with guidance) on tiny frames.

Hard cases: a batch of one, an all-background target, guidance 0, 1 and 8, a model whose
output is far outside the target range (must not be clipped), identical seeds, batch 1 vs
batch N (float32 rounding only), learning on a deterministic toy map, the PatchGAN receptive
field against a gradient measurement, and the weights file (round trip, same bytes, wrong
keys, tampering).
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pandas as pd
import pytest
import torch
from safetensors import safe_open
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors
from scipy import ndimage

from tacgen_lib.generate.pixel.ddpm import (
    fit_pixel_ddpm,
    guided_unet_output,
    sample_pixel_ddpm,
    unet_output,
)
from tacgen_lib.generate.pixel.pix2pix import (
    PatchDiscriminator,
    fit_pix2pix,
    receptive_field,
    translate,
)
from tacgen_lib.generate.pixel.settings import (
    Pix2PixSettings,
    PixelDDPMSettings,
    frames_tensor,
)
from tacgen_lib.generate.pixel.weights import load_pixel_generator, save_pixel_generator
from tacgen_lib.generate.sampling import predicted_x0_eps
from tacgen_lib.io import hashed
from tacgen_lib.io.config import ConfigError

SIZE = (8, 16)
EPS32 = float(np.finfo(np.float32).eps)
#: The toy map's channel mix (rows: tactile channels, columns: RGB channels).
MIX = np.array([[0.6, 0.3, 0.1], [0.1, 0.7, 0.2], [0.3, 0.0, 0.7]])


def toy_pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """RGB: smooth random frames in (-1, 1). Tactile: a fixed deterministic function of the
    RGB frame -- the channel mix MIX, shifted one pixel right, Gaussian-blurred (sigma 1),
    scaled by 0.8 and kept in the tactile range [-1, 127/128]."""
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((n, 3, *SIZE))
    rgb = np.tanh(3 * ndimage.gaussian_filter(noise, sigma=(0, 0, 1, 1)))
    tac = np.einsum("ij,njhw->nihw", MIX, rgb)
    tac = ndimage.gaussian_filter(np.roll(tac, 1, axis=-1), sigma=(0, 0, 1, 1))
    return rgb.astype(np.float32), np.clip(0.8 * tac, -1, 127 / 128).astype(np.float32)


@pytest.fixture(scope="module")
def data() -> dict[str, np.ndarray]:
    rgb_tr, tac_tr = toy_pairs(64, 0)
    rgb_va, tac_va = toy_pairs(32, 1)
    return {"rgb_tr": rgb_tr, "tac_tr": tac_tr, "rgb_va": rgb_va, "tac_va": tac_va}


def _fit(fit_fn, settings, data, seed=0):
    return fit_fn(
        data["rgb_tr"], data["tac_tr"], data["rgb_va"], data["tac_va"], settings, seed, device="cpu"
    )


@pytest.fixture(scope="module")
def p2p(data, request):
    """A tiny pix2pix, trained once for the module (on the session's torch thread count)."""
    before = torch.get_num_threads()
    torch.set_num_threads(request.config.getoption("--torch-threads"))
    try:
        return _fit(fit_pix2pix, Pix2PixSettings.tiny(steps=60), data)
    finally:
        torch.set_num_threads(before)


@pytest.fixture(scope="module")
def ddpm(data, request):
    """A tiny pixel DDPM (v-prediction), trained once for the module."""
    before = torch.get_num_threads()
    torch.set_num_threads(request.config.getoption("--torch-threads"))
    try:
        return _fit(fit_pixel_ddpm, PixelDDPMSettings.tiny(), data)
    finally:
        torch.set_num_threads(before)


def rounding_atol(frames: np.ndarray, passes: int = 1) -> float:
    """How far two computations of the same frames may differ where only kernels differ
    (another batch shape, or a reloaded model's kernel path): one U-Net pass rounds at a few
    eps x |x|, and each of `passes` DDIM steps combines two outputs with coefficients <= 1 and
    may add as much again: 16 passes eps32 max(1, |x|)."""
    return 16 * passes * EPS32 * max(1.0, float(np.abs(frames).max()))


def sample_kw(fit, **changes):
    kw = {
        "schedule": fit.schedule,
        "prediction": fit.settings.prediction,
        "steps": 5,
        "guidance": 1.0,
        "eta": 0.0,
        "seed": 7,
        "batch": 256,
    }
    return {**kw, **changes}


# ------------------------------------------------------------------ settings and frames


def test_settings_from_config_shape_of_the_issue():
    p = Pix2PixSettings.from_config(
        {"channels": [32, 64, 128], "disc_channels": [32, 64], "dropout": 0.5, "lambda_l1": 100}
    )
    assert p == Pix2PixSettings() and p.channels == (32, 64, 128)
    d = PixelDDPMSettings.from_config({"channels": [16, 32, 32], "prediction": "v", "eta": 0.0})
    assert d == PixelDDPMSettings()
    with pytest.raises(ConfigError, match="pixel.ddpm.lambda_l1"):
        PixelDDPMSettings.from_config({"lambda_l1": 100})
    with pytest.raises(ValueError, match="pixel.ddpm.channels"):
        PixelDDPMSettings(channels=(12, 24))  # GroupNorm with 8 groups


def test_frames_refused_with_the_reason():
    with pytest.raises(ValueError, match=r"rgb: expected frames of shape \(N, 3, H, W\)"):
        frames_tensor(np.zeros((2, 1, 8, 16)), "rgb")
    with pytest.raises(ValueError, match="multiple of 8"):
        frames_tensor(np.zeros((2, 3, 12, 16)), "rgb", divisor=8)
    bad = np.zeros((3, 3, 8, 16), dtype=np.float32)
    bad[2, 0, 1, 1] = np.nan
    with pytest.raises(ValueError, match="frame 2 has NaN"):
        frames_tensor(bad, "tac")


# ------------------------------------------------------------------ shapes and hard frames


def test_batch_of_one_keeps_shapes(p2p, ddpm, data):
    one = data["rgb_va"][:1]
    out = translate(p2p.model, one, batch=256)
    assert out.shape == (1, 3, *SIZE) and out.dtype == np.float32
    frames = sample_pixel_ddpm(ddpm.model, one, **sample_kw(ddpm, guidance=2.0, eta=1.0))
    assert frames.shape == (1, 3, *SIZE) and frames.dtype == np.float32
    assert translate(p2p.model, data["rgb_va"][:0], batch=256).shape == (0, 3, *SIZE)


def test_all_background_target_trains_finite(data):
    """Every tactile frame is no-contact (all zeros): no NaN in training or output."""
    zeros = np.zeros_like(data["tac_tr"])
    zeros_va = np.zeros_like(data["tac_va"])
    rgb, rgb_va = data["rgb_tr"], data["rgb_va"]
    p = fit_pix2pix(
        rgb, zeros, rgb_va, zeros_va, Pix2PixSettings.tiny(steps=20), seed=1, device="cpu"
    )
    d = fit_pixel_ddpm(
        rgb, zeros, rgb_va, zeros_va, PixelDDPMSettings.tiny(steps=20), seed=1, device="cpu"
    )
    for fit in (p, d):
        assert np.isfinite(fit.curve.iloc[1:].to_numpy()).all()
    assert np.isfinite(translate(p.model, rgb_va, batch=256)).all()
    assert np.isfinite(sample_pixel_ddpm(d.model, rgb_va[:4], **sample_kw(d, eta=1.0))).all()


def test_outputs_are_never_clipped(p2p, ddpm, data):
    """A model biased far outside [-1, 127/128] must show it, in both generators."""
    g = copy.deepcopy(p2p.model)
    with torch.no_grad():
        g.out.bias += 4.0
    assert translate(g, data["rgb_va"], batch=256).mean() > 3.0
    u = copy.deepcopy(ddpm.model)
    with torch.no_grad():
        u.conv_out.bias += 4.0  # v + 4: x0 = sqrt(abar) x_t - sqrt(1 - abar) (v + 4)
    frames = sample_pixel_ddpm(u, data["rgb_va"][:4], **sample_kw(ddpm, steps=1))
    assert frames.mean() < -3.0


# ------------------------------------------------------------------ guidance


def test_guidance_passes_and_combination(ddpm, data):
    x = np.random.default_rng(3).standard_normal((6, 3, *SIZE)).astype(np.float32)
    rgb, t = data["rgb_va"][:6], 40
    with torch.inference_mode():
        args = (ddpm.model, torch.from_numpy(x), torch.full((6,), t), torch.from_numpy(rgb))
        out_c = unet_output(*args, None).numpy()
        out_u = unet_output(*args, torch.ones(6, dtype=torch.bool)).numpy()
    # w = 1 runs only the conditional pass and w = 0 only the unconditional one: exact
    np.testing.assert_array_equal(guided_unet_output(ddpm.model, x, t, rgb, 1.0), out_c)
    np.testing.assert_array_equal(guided_unet_output(ddpm.model, x, t, rgb, 0.0), out_u)
    assert not np.array_equal(out_c, out_u)  # the condition matters
    # both passes in one batch of 12 vs by hand from two batches of 6: each pass may round
    # differently (delta <= a few eps x |out|), and out_u + w (out_c - out_u) carries at most
    # (1 + 2w) delta; bound with 16 eps per unit
    w = 2.5
    scale = max(np.abs(out_c).max(), np.abs(out_u).max())
    np.testing.assert_allclose(
        guided_unet_output(ddpm.model, x, t, rgb, w),
        out_u + w * (out_c - out_u),
        rtol=0,
        atol=16 * (1 + 2 * w) * EPS32 * scale,
    )


def test_one_ddim_step_is_the_guided_x0(ddpm, data):
    """steps = 1 ends at abar_prev = 1: the sample is the unclipped x0 of the guided output
    at t = T - 1 from the seed's initial noise, bit for bit (the same arithmetic)."""
    rgb, w, seed = data["rgb_va"][:3], 2.5, 11
    got = sample_pixel_ddpm(ddpm.model, rgb, **sample_kw(ddpm, steps=1, guidance=w, seed=seed))
    sch = ddpm.schedule
    t = sch.n_steps - 1
    x_t = np.random.default_rng(seed).standard_normal(rgb.shape, dtype=np.float32)
    out = guided_unet_output(ddpm.model, x_t, t, rgb, w)
    sa = np.sqrt(sch.alphas_cumprod).astype(np.float32)[t]
    s1 = np.sqrt(sch.one_minus_alphas_cumprod).astype(np.float32)[t]
    x0, _ = predicted_x0_eps(out, x_t, sa, s1, "v")
    np.testing.assert_array_equal(got, x0)


@pytest.mark.parametrize("w", [0.0, 8.0])
def test_extreme_guidance_is_finite(ddpm, data, w):
    frames = sample_pixel_ddpm(ddpm.model, data["rgb_va"][:4], **sample_kw(ddpm, guidance=w))
    assert np.isfinite(frames).all()


# ------------------------------------------------------------------ determinism


def test_same_seed_same_frames_bit_for_bit(p2p, ddpm, data):
    rgb = data["rgb_va"][:6]
    np.testing.assert_array_equal(
        translate(p2p.model, rgb, batch=256), translate(p2p.model, rgb, batch=256)
    )
    kw = sample_kw(ddpm, guidance=2.0, eta=0.5)
    a = sample_pixel_ddpm(ddpm.model, rgb, **kw)
    np.testing.assert_array_equal(a, sample_pixel_ddpm(ddpm.model, rgb, **kw))
    assert not np.allclose(a, sample_pixel_ddpm(ddpm.model, rgb, **{**kw, "seed": 8}))


@pytest.mark.parametrize("w, eta", [(1.0, 0.0), (3.0, 1.0)])
def test_batch_one_vs_batch_n_within_float32_rounding(p2p, ddpm, data, w, eta):
    """The noise covers all rows up front, so only the U-Net's batched kernels differ: within
    `rounding_atol` of the S DDIM steps."""
    rgb = data["rgb_va"][:8]
    steps = 5
    kw = sample_kw(ddpm, steps=steps, guidance=w, eta=eta)
    one = sample_pixel_ddpm(ddpm.model, rgb, **{**kw, "batch": 1})
    many = sample_pixel_ddpm(ddpm.model, rgb, **{**kw, "batch": 8})
    np.testing.assert_allclose(one, many, rtol=0, atol=rounding_atol(many, steps))
    g1, g8 = translate(p2p.model, rgb, batch=1), translate(p2p.model, rgb, batch=8)
    np.testing.assert_allclose(g1, g8, rtol=0, atol=rounding_atol(g8))


# ------------------------------------------------------------------ learning


def test_pix2pix_learns_the_toy_map(p2p, data):
    """Untrained G outputs ~0 (weights ~ N(0, 0.02)): its val L1 is that of predicting the
    background; after 60 tiny steps the kept G must at least halve it."""
    init = p2p.curve.loc[p2p.curve.step == 0, "val_l1"].item()
    assert init == pytest.approx(float(np.abs(data["tac_va"]).mean()), rel=0.2)
    assert p2p.best_val < 0.5 * init and p2p.best_step > 0
    again = np.mean(np.abs(translate(p2p.model, data["rgb_va"], batch=256) - data["tac_va"]))
    assert again == pytest.approx(p2p.best_val, rel=1e-6)  # the kept G is the best one


def test_ddpm_val_loss_falls(ddpm):
    curve = ddpm.curve
    init = curve.loc[curve.step == 0, "val_loss"].item()
    assert ddpm.best_val < 0.75 * init and ddpm.best_step > 0
    assert list(curve.columns) == ["step", "train_loss", "val_loss"]


# ------------------------------------------------------------------ PatchGAN


@pytest.mark.parametrize("disc", [(4,), (4, 8), (4, 8, 8)])
def test_receptive_field_matches_gradient(disc):
    """The input pixels that move one central logit of the real module (eval mode, float64):
    a full square of side receptive_field(disc)."""
    torch.manual_seed(0)
    d = PatchDiscriminator(disc).double().eval()
    rf = receptive_field(disc)
    x = torch.randn(1, 6, 3 * rf, 3 * rf, dtype=torch.float64, requires_grad=True)
    out = d(x[:, :3], x[:, 3:])
    out[0, 0, out.shape[2] // 2, out.shape[3] // 2].backward()
    seen = (x.grad[0].abs().sum(0) > 0).numpy()
    rows, cols = np.flatnonzero(seen.any(1)), np.flatnonzero(seen.any(0))
    assert (rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1) == (rf, rf)
    assert seen.sum() == rf * rf
    assert 0 < rows[0] and rows[-1] < 3 * rf - 1  # away from the padded border


# ------------------------------------------------------------------ weights file


@pytest.mark.parametrize("kind", ["pix2pix", "ddpm"])
def test_weights_round_trip_and_same_bytes(kind, p2p, ddpm, data, tmp_path):
    fit = p2p if kind == "pix2pix" else ddpm
    a, b = tmp_path / "a.safetensors", tmp_path / "b.safetensors"
    save_pixel_generator(fit, a, kind=kind)
    save_pixel_generator(fit, b, kind=kind)
    assert a.read_bytes() == b.read_bytes()
    back = load_pixel_generator(a)
    assert type(back) is type(fit) and back.settings == fit.settings
    for f in ("seed", "size", "best_step", "best_val", "steps_run", "stopped_early"):
        assert getattr(back, f) == getattr(fit, f), f
    pd.testing.assert_frame_equal(back.curve, fit.curve)
    # the file gives back every weight bit for bit (a data move)...
    state, back_state = fit.model.state_dict(), back.model.state_dict()
    assert state.keys() == back_state.keys()
    for k, v in state.items():
        assert torch.equal(back_state[k], v), k
    # ...but the reloaded model is another computation: torch may pick its kernels by the
    # weights' flags (the fit's EMA U-Net needs no gradient, the loaded one's weights do), so
    # the two models' frames agree within rounding (`rounding_atol`), not bit for bit
    rgb = data["rgb_va"][:5]
    if kind == "pix2pix":
        got, want = translate(back.model, rgb, batch=256), translate(fit.model, rgb, batch=256)
        np.testing.assert_allclose(got, want, rtol=0, atol=rounding_atol(want))
    else:
        kw = sample_kw(fit, guidance=2.0, eta=1.0)
        got, want = (
            sample_pixel_ddpm(back.model, rgb, **kw),
            sample_pixel_ddpm(fit.model, rgb, **kw),
        )
        np.testing.assert_allclose(got, want, rtol=0, atol=rounding_atol(want, kw["steps"]))
    with pytest.raises(ValueError, match="does not match the fit"):
        save_pixel_generator(fit, tmp_path / "c", kind="ddpm" if kind == "pix2pix" else "pix2pix")


@pytest.mark.parametrize("kind", ["pix2pix", "ddpm"])
def test_same_seed_same_weights_file(kind, p2p, ddpm, data, tmp_path):
    """Training again with the same inputs and seed gives the same bytes, and leaves the
    caller's global torch RNG where it was."""
    fit = p2p if kind == "pix2pix" else ddpm
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    again = _fit(fit_pix2pix if kind == "pix2pix" else fit_pixel_ddpm, fit.settings, data)
    assert torch.equal(torch.rand(3), expected)
    save_pixel_generator(fit, tmp_path / "a", kind=kind)
    save_pixel_generator(again, tmp_path / "b", kind=kind)
    assert (tmp_path / "a").read_bytes() == (tmp_path / "b").read_bytes()
    other = _fit(fit_pix2pix, dataclasses.replace(p2p.settings, steps=10), data, seed=1)
    assert not torch.equal(other.model.out.weight, p2p.model.out.weight)


def test_weights_with_wrong_keys_or_bytes_refused(p2p, tmp_path):
    good = tmp_path / "good.safetensors"
    save_pixel_generator(p2p, good, kind="pix2pix")
    with safe_open(good, "pt") as fh:
        meta = fh.metadata()
    tensors = load_tensors(good.read_bytes())
    tensors.pop("out.bias")
    tensors["stray.weight"] = torch.zeros(2)
    bad = tmp_path / "bad.safetensors"
    hashed.write_bytes(bad, save_tensors(tensors, metadata=meta), rows=1, key="generator")
    with pytest.raises(ValueError, match=r"bad\.safetensors.*out\.bias.*stray\.weight"):
        load_pixel_generator(bad)
    raw = bytearray(good.read_bytes())
    raw[-1] ^= 1
    good.write_bytes(bytes(raw))
    with pytest.raises(hashed.EdgeError, match="does not match the manifest"):
        load_pixel_generator(good)
