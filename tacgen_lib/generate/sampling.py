"""Samplers of the latent generator: DDPM ancestral and DDIM, with classifier-free guidance.

This module owns turning a trained denoiser into tactile feature vectors, in numpy on the
denoiser's arrays (`inference.DenoiserArrays`), so a sampling job never imports torch:

- `guided_output`: eps^ = eps_u + w (eps_c - eps_u) (Ho & Salimans 2022), the conditional and
  unconditional passes in one batch (w = 1: the plain conditional model; w = 0: unconditional).
  `guided_output_projected` is the same at one shared timestep with the condition's share of
  the embeddings computed once per batch (`project_guidance`); `sample` uses it. It runs only
  the passes w needs (`guidance_passes`): both in one batch in general, the conditional pass
  alone at w = 1 and the unconditional alone at w = 0, where the other term cancels (exactly
  eps_c or eps_u, not the rounding of eps_u + 1 (eps_c - eps_u); half the FLOPs).
  With v-prediction the same combination is applied to v (linear in eps, so equivalent).
- `predicted_x0_eps`: (x0, eps) from the model output (eps- or v-prediction).
- `ddpm_step`: ancestral step with the posterior mean/variance (DDPM eq. 6-7), over all T.
- `ddim_step`: DDIM eq. 12 with eta (eta = 0: deterministic), over any subsequence of steps.
- `generate`: `sample` for a trained generator, back in the tactile feature's own units.

Nothing is clipped: the features are standardised, unbounded vectors (diffusers' default
``clip_sample=True`` would clamp x0 to [-1, 1] and silently damage them).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tacgen_lib.generate.inference import DenoiserArrays, GeneratorWeights
from tacgen_lib.generate.sampling_cells import guidance_passes
from tacgen_lib.generate.schedules import Schedule

__all__ = [
    "ddim_step",
    "ddim_timesteps",
    "ddpm_step",
    "generate",
    "guided_output",
    "guided_output_projected",
    "predicted_x0_eps",
    "project_guidance",
    "sample",
    "sampling_plan",
]


def guided_output(
    model: DenoiserArrays, x_t: np.ndarray, t: np.ndarray, cond: np.ndarray, guidance: float
) -> np.ndarray:
    """Classifier-free guidance: out_u + w (out_c - out_u), both passes in one batch of 2B."""
    b = x_t.shape[0]
    drop = np.concatenate([np.zeros(b, dtype=bool), np.ones(b, dtype=bool)])
    out = model.forward(
        np.concatenate([x_t, x_t]), np.concatenate([t, t]), np.concatenate([cond, cond]), drop
    )
    out_c, out_u = out[:b], out[b:]
    return out_u + guidance * (out_c - out_u)


def project_guidance(model: DenoiserArrays, cond: np.ndarray, guidance: float) -> list[np.ndarray]:
    """The condition's share of every block's embedding for the passes of `guidance_passes`:
    ``model.project_condition`` of one copy of `cond` per pass (conditional copy first)."""
    passes = guidance_passes(guidance)
    drop = np.repeat(np.array(passes, dtype=bool), cond.shape[0])
    return model.project_condition(np.concatenate([cond] * len(passes)), drop)


def guided_output_projected(
    model: DenoiserArrays, x_t: np.ndarray, t: int, projected: list[np.ndarray], guidance: float
) -> np.ndarray:
    """`guided_output` at one shared timestep with the condition part precomputed:
    `projected` = ``project_guidance(model, cond, guidance)``. Equal to `guided_output` up to
    float rounding; `sample` uses it. At w = 0 or 1 one pass runs (`guidance_passes`)."""
    if len(guidance_passes(guidance)) == 1:
        return model.forward_projected(x_t, t, projected)
    b = x_t.shape[0]
    out = model.forward_projected(np.concatenate([x_t, x_t]), t, projected)
    out_c, out_u = out[:b], out[b:]
    return out_u + guidance * (out_c - out_u)


def predicted_x0_eps(
    out: np.ndarray, x_t: np.ndarray, sqrt_abar: float, sqrt_1m_abar: float, prediction: str
) -> tuple[np.ndarray, np.ndarray]:
    """(x0, eps) from the model output at one step; no clipping (features are unbounded).

    eps-prediction: x0 = (x_t - sqrt(1 - abar) eps) / sqrt(abar) (DDIM eq. 12's "predicted x0").
    v-prediction: x0 = sqrt(abar) x_t - sqrt(1 - abar) v, eps = sqrt(1 - abar) x_t + sqrt(abar) v.
    """
    if prediction == "eps":
        return (x_t - sqrt_1m_abar * out) / sqrt_abar, out
    if prediction == "v":
        return sqrt_abar * x_t - sqrt_1m_abar * out, sqrt_1m_abar * x_t + sqrt_abar * out
    raise ValueError(f"prediction must be 'eps' or 'v', got {prediction!r}")


def ddpm_step(
    x0: np.ndarray, x_t: np.ndarray, t: int, coef: dict[str, np.ndarray], noise: np.ndarray | None
) -> np.ndarray:
    """One ancestral step x_t -> x_{t-1} ~ N(mu~_t(x_t, x0), beta~_t) (DDPM eq. 6-7).

    1. posterior mean mu~ = coef1_t x0 + coef2_t x_t
    2. add sqrt(beta~_t) z, except at t = 0 (the last step returns the mean)
    """
    mean = coef["posterior_mean_coef1"][t] * x0 + coef["posterior_mean_coef2"][t] * x_t
    if t == 0 or noise is None:
        return mean
    return mean + np.exp(0.5 * coef["posterior_log_variance"][t]) * noise


def ddim_step(
    x0: np.ndarray,
    eps: np.ndarray,
    abar_t: float,
    abar_prev: float,
    eta: float,
    noise: np.ndarray | None,
) -> np.ndarray:
    """One DDIM step x_t -> x_{t_prev} (Song et al. 2021, eq. 12), alpha-bars in float64.

    1. sigma = eta sqrt((1 - abar_prev) / (1 - abar_t)) sqrt(1 - abar_t / abar_prev)
    2. direction pointing to x_t: sqrt(1 - abar_prev - sigma^2) eps
    3. x_prev = sqrt(abar_prev) x0 + direction + sigma z
    """
    sigma = 0.0
    if eta > 0 and abar_prev < 1.0:
        sigma = (
            eta * np.sqrt((1.0 - abar_prev) / (1.0 - abar_t)) * np.sqrt(1.0 - abar_t / abar_prev)
        )
    direction = float(np.sqrt(max(1.0 - abar_prev - sigma**2, 0.0)))
    x_prev = np.float32(np.sqrt(abar_prev)) * x0 + np.float32(direction) * eps
    if sigma > 0 and noise is not None:
        x_prev = x_prev + np.float32(sigma) * noise
    return x_prev


def ddim_timesteps(n_train: int, steps: int) -> np.ndarray:
    """`steps` timesteps from T-1 down to 0, evenly spaced ("linear" spacing), strictly decreasing."""
    if not 1 <= steps <= n_train:
        raise ValueError(f"DDIM steps must be in 1..{n_train}, got {steps}")
    if steps == 1:
        return np.array([n_train - 1])
    ts = np.round(np.linspace(n_train - 1, 0, steps)).astype(np.int64)
    return np.unique(ts)[::-1].copy()


def sampling_plan(
    schedule: Schedule, sampler: str, steps: int, prediction: str
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What every sampler of the latent generator (`sample`, `sampling_torch.sample_torch`)
    runs on, after checking `sampler`, `prediction` and `steps`: the
    schedule's float32 coefficients (`Schedule.arrays`), abar_t (float64), sqrt(abar_t) and
    sqrt(1 - abar_t) (float32), and the timesteps, T-1 down to 0 for ``ddpm`` (which runs all
    T) or `ddim_timesteps(T, steps)` for ``ddim``."""
    if sampler not in ("ddpm", "ddim"):
        raise ValueError(f"sampler must be 'ddpm' or 'ddim', got {sampler!r}")
    if prediction not in ("eps", "v"):
        raise ValueError(f"prediction must be 'eps' or 'v', got {prediction!r}")
    T = schedule.n_steps
    if sampler == "ddpm" and steps != T:
        raise ValueError(f"DDPM ancestral sampling runs all T = {T} steps, got steps = {steps}")
    coef = schedule.arrays(np.float32)
    abar64 = schedule.alphas_cumprod
    sqrt_abar = np.sqrt(abar64).astype(np.float32)
    sqrt_1m = np.sqrt(schedule.one_minus_alphas_cumprod).astype(np.float32)
    ts = np.arange(T - 1, -1, -1) if sampler == "ddpm" else ddim_timesteps(T, steps)
    return coef, abar64, sqrt_abar, sqrt_1m, ts


def sample(
    model: DenoiserArrays,
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
    """Standardised tactile features for each condition row (n, d_v) -> (n, d_t) float64.

    Computed in float32. Noise comes from one numpy Generator (PCG64) seeded with `seed`,
    drawn batch after batch in row order, so the same seed, rows and batch give the same
    vectors (bit for bit on one machine). ``ddpm`` runs all T steps (`steps` must equal T);
    ``ddim`` runs `ddim_timesteps(T, steps)`.
    """
    coef, abar64, sqrt_abar, sqrt_1m, ts = sampling_plan(schedule, sampler, steps, prediction)
    rng = np.random.default_rng(int(seed))
    cond32 = np.ascontiguousarray(cond, dtype=np.float32)
    d_t = model.dims["dim_t"]
    out = []
    for start in range(0, cond32.shape[0], batch):
        c = cond32[start : start + batch]
        x = rng.standard_normal((c.shape[0], d_t), dtype=np.float32)
        # the condition's share of every block's embedding: once per batch, not per step
        projected = project_guidance(model, c, guidance)
        for i, t in enumerate(ts):
            t = int(t)
            o = guided_output_projected(model, x, t, projected, guidance)
            x0, eps = predicted_x0_eps(o, x, sqrt_abar[t], sqrt_1m[t], prediction)
            if sampler == "ddpm":
                noise = rng.standard_normal(x.shape, dtype=np.float32) if t > 0 else None
                x = ddpm_step(x0, x, t, coef, noise)
            else:
                t_prev = int(ts[i + 1]) if i + 1 < len(ts) else -1
                abar_prev = float(abar64[t_prev]) if t_prev >= 0 else 1.0
                draw = eta > 0 and t_prev >= 0
                noise = rng.standard_normal(x.shape, dtype=np.float32) if draw else None
                x = ddim_step(x0, eps, float(abar64[t]), abar_prev, eta, noise)
        out.append(x.astype(np.float64))
    if not out:
        return np.zeros((0, d_t))
    return np.concatenate(out)


def generate(weights: GeneratorWeights, cond: np.ndarray, **sample_kw: Any) -> np.ndarray:
    """Generated tactile features in the original (unstandardised) units, float32 (n, d_t):
    `sample` with the generator's denoiser, schedule and prediction, then un-standardised."""
    z = sample(
        weights.denoiser,
        weights.schedule,
        cond,
        prediction=weights.settings.prediction,
        **sample_kw,
    )
    return weights.standardiser.inverse(z).astype(np.float32)
