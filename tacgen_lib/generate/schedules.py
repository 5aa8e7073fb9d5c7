"""Noise schedules of the latent diffusion generator, as pure functions (DDPM, Ho et al. 2020).

This module owns beta_t, alpha-bar_t and the posterior q(x_{t-1} | x_t, x_0) coefficients.
Everything is computed in float64 and stored as float32 tensors only at the end, so the
hard cases stay finite:

- cosine (Nichol & Dhariwal 2021, eq. 17): alpha-bar from a squared cosine with offset s,
  beta clipped at 0.999 so that beta_T < 1 and alpha-bar_T > 0 (its unclipped last beta is 1,
  which makes alpha-bar_T exactly 0 and 1/sqrt(alpha-bar_T) infinite);
- linear (Ho et al. 2020): beta from 1e-4 to 0.02 scaled to T.

At t = 0 the cosine alpha-bar is 1 - 4e-5 in float64 but rounds towards 1 in float32; the
quantities that divide by (1 - alpha-bar) or take logs of the posterior variance are therefore
formed in float64 (`posterior_log_variance` is clipped at t = 0 to the t = 1 value, as in
the DDPM code, because the true posterior variance at t = 0 is 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "SCHEDULES",
    "Schedule",
    "cosine_betas",
    "linear_betas",
    "make_schedule",
]

#: Largest beta of the cosine schedule (Nichol & Dhariwal: "clip beta_t to be no larger than 0.999").
MAX_BETA = 0.999


def cosine_betas(n_steps: int, s: float = 0.008, max_beta: float = MAX_BETA) -> np.ndarray:
    """Betas of the cosine schedule (float64): alpha-bar(t) = f(t)/f(0), f = cos^2(((t/T)+s)/(1+s) pi/2)."""
    if n_steps < 1:
        raise ValueError(f"generate.train_steps must be >= 1, got {n_steps}")
    t = np.arange(n_steps + 1, dtype=np.float64) / n_steps
    f = np.cos((t + s) / (1.0 + s) * math.pi / 2.0) ** 2
    alpha_bar = f / f[0]
    betas = 1.0 - alpha_bar[1:] / alpha_bar[:-1]
    return np.clip(betas, 0.0, max_beta)


def linear_betas(n_steps: int, start: float = 1e-4, end: float = 0.02) -> np.ndarray:
    """Betas of the linear schedule (float64), scaled so T != 1000 keeps the same alpha-bar_T."""
    if n_steps < 1:
        raise ValueError(f"generate.train_steps must be >= 1, got {n_steps}")
    scale = 1000.0 / n_steps
    return np.linspace(start * scale, min(end * scale, MAX_BETA), n_steps, dtype=np.float64)


SCHEDULES = {"cosine": cosine_betas, "linear": linear_betas}


@dataclass(frozen=True)
class Schedule:
    """A noise schedule of T steps; index t = 0 .. T-1 (t = 0 is the least noisy step).

    The float64 arrays are the reference; `arrays` gives float32 copies for sampling.
    """

    name: str
    betas: np.ndarray  # (T,) float64
    alphas_cumprod: np.ndarray  # (T,) float64: alpha-bar_t
    alphas_cumprod_prev: np.ndarray  # (T,) alpha-bar_{t-1}, with alpha-bar_{-1} = 1
    posterior_variance: np.ndarray  # (T,) beta~_t = beta_t (1 - abar_{t-1}) / (1 - abar_t)
    posterior_log_variance: np.ndarray  # (T,) log beta~_t, clipped at t = 0
    posterior_mean_coef1: np.ndarray  # (T,) coefficient of x0 in mu~_t (DDPM eq. 7)
    posterior_mean_coef2: np.ndarray  # (T,) coefficient of x_t in mu~_t
    one_minus_alphas_cumprod: np.ndarray  # (T,) 1 - alpha-bar_t, exact near t = 0 (expm1)

    @property
    def n_steps(self) -> int:
        return int(self.betas.size)

    _NAMES = (
        "betas",
        "alphas_cumprod",
        "alphas_cumprod_prev",
        "posterior_variance",
        "posterior_log_variance",
        "posterior_mean_coef1",
        "posterior_mean_coef2",
        "one_minus_alphas_cumprod",
    )

    def arrays(self, dtype: type = np.float32) -> dict[str, np.ndarray]:
        """Every coefficient as an array of `dtype` (cast from the float64 reference)."""
        return {n: getattr(self, n).astype(dtype) for n in self._NAMES}


def make_schedule(name: str, n_steps: int) -> Schedule:
    """The schedule `name` ("cosine" | "linear") with T = `n_steps`, coefficients in float64."""
    if name not in SCHEDULES:
        raise ValueError(f"generate.schedule must be one of {sorted(SCHEDULES)}, got {name!r}")
    betas = SCHEDULES[name](n_steps)
    alphas = 1.0 - betas
    abar = np.cumprod(alphas)
    abar_prev = np.concatenate([[1.0], abar[:-1]])
    # 1 - abar_t in float64 via expm1(sum log alphas): exact near t = 0 where abar ~ 1.
    one_minus_abar = -np.expm1(np.cumsum(np.log1p(-betas)))
    one_minus_abar_prev = np.concatenate([[0.0], one_minus_abar[:-1]])
    post_var = betas * one_minus_abar_prev / one_minus_abar
    # The posterior variance is 0 at t = 0; its log is clipped to the t = 1 value (DDPM code).
    post_log_var = (
        np.log(np.concatenate([post_var[1:2], post_var[1:]]))
        if n_steps > 1
        else (np.log(np.maximum(betas, 1e-20)))
    )
    coef1 = betas * np.sqrt(abar_prev) / one_minus_abar
    coef2 = one_minus_abar_prev * np.sqrt(alphas) / one_minus_abar
    return Schedule(
        name, betas, abar, abar_prev, post_var, post_log_var, coef1, coef2, one_minus_abar
    )
