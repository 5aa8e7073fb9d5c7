"""The torch twin of the latent generator's sampler (tacgen_lib.generate.sampling_torch), which
a GPU run samples with: on the CPU it must give the numpy sampler's vectors within float
rounding (same noise, same steps; different kernels and the condition's share computed per
step, not once), for both samplers, both predictions and the guidance extremes."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tacgen_lib.generate.sampling import generate
from tacgen_lib.generate.sampling_torch import denoiser_module, generate_torch
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.train import fit_generator


def _pairs(n: int = 200, dv: int = 5, dt: int = 4, seed: int = 0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, dv))
    t = v @ rng.normal(size=(dv, dt)) + 0.1 * rng.normal(size=(n, dt))
    return t, v


@pytest.fixture(scope="module", params=["eps", "v"])
def weights(request):
    """A tiny trained generator (not zero weights: the output layer starts at zero)."""
    t, v = _pairs()
    s = GenerateSettings.tiny(prediction=request.param)
    return fit_generator(t[:150], v[:150], t[150:], v[150:], s, seed=3, device="cpu").weights()


@pytest.mark.parametrize(
    ("sampler", "steps", "guidance", "eta"),
    [
        ("ddim", 10, 1.0, 0.0),  # deterministic, conditional pass alone
        ("ddim", 10, 0.0, 0.0),  # unconditional pass alone
        ("ddim", 7, 2.5, 0.5),  # both passes, stochastic DDIM
        ("ddpm", 100, 1.5, 0.0),  # ancestral over all T
    ],
)
def test_the_torch_sampler_equals_the_numpy_one_on_the_cpu(weights, sampler, steps, guidance, eta):
    cond = np.random.default_rng(1).normal(size=(37, 5))
    kw = dict(sampler=sampler, steps=steps, guidance=guidance, seed=11, eta=eta, batch=16)
    ref = generate(weights, cond, **kw)
    got = generate_torch(weights, cond, device="cpu", **kw)
    assert got.dtype == ref.dtype == np.float32 and got.shape == ref.shape == (37, 4)
    assert np.isfinite(got).all()
    scale = float(np.abs(ref).max())
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-4 * scale)
    # the noise matters (another seed moves the vectors far beyond rounding)
    other = generate_torch(weights, cond, device="cpu", **{**kw, "seed": 12})
    if sampler == "ddpm" or eta > 0 or guidance == 0.0:
        assert np.abs(other - got).max() > 100 * 1e-4 * scale


def test_the_torch_denoiser_is_the_trained_one(weights):
    model = denoiser_module(weights, device="cpu")
    assert not model.training and next(model.parameters()).device.type == "cpu"
    x = torch.randn(3, 4, generator=torch.Generator().manual_seed(0))
    c = torch.randn(3, 5, generator=torch.Generator().manual_seed(1))
    t = np.array([0, 5, 99])
    got = model(x, torch.from_numpy(t), c).detach().numpy()
    ref = weights.denoiser.forward(x.numpy(), t, c.numpy())
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-6)


def test_the_torch_sampler_refuses_what_the_numpy_one_refuses(weights):
    cond = np.zeros((2, 5))
    with pytest.raises(ValueError, match="sampler"):
        generate_torch(
            weights,
            cond,
            device="cpu",
            sampler="euler",
            steps=5,
            guidance=1,
            seed=0,
            eta=0.0,
            batch=2048,
        )
    with pytest.raises(ValueError, match="all T"):
        generate_torch(
            weights,
            cond,
            device="cpu",
            sampler="ddpm",
            steps=5,
            guidance=1,
            seed=0,
            eta=0.0,
            batch=2048,
        )
