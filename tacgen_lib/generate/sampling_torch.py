"""The latent generator's samplers in torch, for a GPU: the same DDPM / DDIM steps with
classifier-free guidance as `sampling` (numpy), on any torch device.

`sampling.sample` stays the sampler of a CPU run (numpy only: a sampling job on the CPU imports
no torch, and its edges stay bit-identical). This module is its twin where `device` is a GPU
(`tacgen_lib.runtime.device`): the same noise (one numpy Generator seeded with `seed`, drawn in
the same order, moved to the device), the same steps in float32, the same guided output with
only the passes w needs (`sampling_cells.guidance_passes`). The two agree within float rounding
(tests/generate/test_sampling_torch.py, on the CPU); the torch denoiser runs the full forward
pass (`model.Denoiser`), not the numpy one's precomputed condition share, a difference of
rounding only.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from tacgen_lib.generate.inference import GeneratorWeights
from tacgen_lib.generate.model import Denoiser
from tacgen_lib.generate.sampling import sampling_plan
from tacgen_lib.generate.sampling_cells import guidance_passes
from tacgen_lib.generate.schedules import Schedule

__all__ = ["denoiser_module", "generate_torch", "guided_output_torch", "sample_torch"]


def denoiser_module(weights: GeneratorWeights, device: torch.device | str) -> Denoiser:
    """The trained denoiser of `weights` as a torch module in eval mode on `device`."""
    d = weights.denoiser.dims
    model = Denoiser(d["dim_t"], d["dim_v"], d["hidden"], d["blocks"], d["time_dim"])
    model.load_state_dict({k: torch.from_numpy(v) for k, v in weights.denoiser.params.items()})
    return model.eval().to(torch.device(device))


def guided_output_torch(
    model: Denoiser, x_t: torch.Tensor, t: int, cond: torch.Tensor, guidance: float
) -> torch.Tensor:
    """out_u + w (out_c - out_u) at one shared timestep t (Ho & Salimans 2022); at w = 1 the
    conditional pass alone, at w = 0 the unconditional alone (`guidance_passes`), as
    `sampling.guided_output_projected`."""
    passes = guidance_passes(guidance)
    b = x_t.shape[0]
    k = len(passes)
    drop = torch.tensor(passes, dtype=torch.bool).repeat_interleave(b).to(x_t.device)
    steps = torch.full((k * b,), int(t), dtype=torch.long)
    out = model(torch.cat([x_t] * k), steps, torch.cat([cond] * k), drop)
    if k == 1:
        return out
    out_c, out_u = out[:b], out[b:]
    return out_u + guidance * (out_c - out_u)


@torch.no_grad()
def sample_torch(
    model: Denoiser,
    schedule: Schedule,
    cond: np.ndarray,
    *,
    sampler: str,
    steps: int,
    guidance: float,
    seed: int,
    prediction: str,
    eta: float,
    batch: int,
) -> np.ndarray:
    """`sampling.sample` with a torch denoiser on its own device: standardised tactile features
    (n, d_t) float64 for condition rows (n, d_v).

    1. x_T ~ N(0, I) per batch, then at each step:
    2. the guided output (`guided_output_torch`) and from it (x0, eps) (DDIM eq. 12's
       "predicted x0"; v-prediction: x0 = sqrt(abar) x_t - sqrt(1 - abar) v)
    3. DDPM: posterior mean coef1 x0 + coef2 x_t plus sqrt(beta~) z except at t = 0 (DDPM eq.
       6-7); DDIM: sqrt(abar_prev) x0 + sqrt(1 - abar_prev - sigma^2) eps + sigma z (eq. 12)
    Noise: numpy Generator(seed) in `sample`'s order, so both samplers use the same numbers.
    """
    coef, abar64, sqrt_abar, sqrt_1m, ts = sampling_plan(schedule, sampler, steps, prediction)
    dev = next(model.parameters()).device
    rng = np.random.default_rng(int(seed))
    cond32 = np.ascontiguousarray(cond, dtype=np.float32)
    d_t = model.dims["dim_t"]

    def normal(shape: tuple[int, ...]) -> torch.Tensor:
        return torch.from_numpy(rng.standard_normal(shape, dtype=np.float32)).to(dev)

    out = []
    for start in range(0, cond32.shape[0], batch):
        c = torch.from_numpy(cond32[start : start + batch]).to(dev)
        x = normal((c.shape[0], d_t))
        for i, t in enumerate(ts):
            t = int(t)
            o = guided_output_torch(model, x, t, c, guidance)
            a, m = float(sqrt_abar[t]), float(sqrt_1m[t])
            if prediction == "eps":
                x0, eps = (x - m * o) / a, o
            else:
                x0, eps = a * x - m * o, m * x + a * o
            if sampler == "ddpm":
                mean = (
                    float(coef["posterior_mean_coef1"][t]) * x0
                    + float(coef["posterior_mean_coef2"][t]) * x
                )
                if t > 0:
                    sd = float(np.exp(0.5 * coef["posterior_log_variance"][t]))
                    x = mean + sd * normal(tuple(x.shape))
                else:
                    x = mean
            else:
                t_prev = int(ts[i + 1]) if i + 1 < len(ts) else -1
                abar_t = float(abar64[t])
                abar_prev = float(abar64[t_prev]) if t_prev >= 0 else 1.0
                sigma = 0.0
                if eta > 0 and abar_prev < 1.0:
                    sigma = float(
                        eta
                        * np.sqrt((1.0 - abar_prev) / (1.0 - abar_t))
                        * np.sqrt(1.0 - abar_t / abar_prev)
                    )
                direction = float(np.sqrt(max(1.0 - abar_prev - sigma**2, 0.0)))
                x = float(np.sqrt(abar_prev)) * x0 + direction * eps
                if eta > 0 and t_prev >= 0:
                    z = normal(tuple(x.shape))
                    if sigma > 0:
                        x = x + sigma * z
        out.append(x.double().cpu().numpy())
    if not out:
        return np.zeros((0, d_t))
    return np.concatenate(out)


def generate_torch(
    weights: GeneratorWeights,
    cond: np.ndarray,
    *,
    device: torch.device | str,
    **sample_kw: Any,
) -> np.ndarray:
    """`sampling.generate` on a torch device: float32 tactile features (n, d_t) in the
    feature's own units."""
    z = sample_torch(
        denoiser_module(weights, device),
        weights.schedule,
        cond,
        prediction=weights.settings.prediction,
        **sample_kw,
    )
    return weights.standardiser.inverse(z).astype(np.float32)
