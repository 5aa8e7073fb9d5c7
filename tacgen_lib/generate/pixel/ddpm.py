"""A pixel-space DDPM: tactile frames denoised by a U-Net conditioned on the RGB frame, with
classifier-free guidance (Ho & Salimans 2022).

This module owns the denoiser (`make_unet`: a diffusers ``UNet2DModel`` on
concat(x_t, RGB), `unet_output`: how the condition enters and is dropped), its training
(`fit_pixel_ddpm`) and DDIM sampling (`guided_unet_output`, `sample_pixel_ddpm`).

What the latent generator already defines is reused, not re-derived: the schedule
(`schedules.make_schedule`), the loss (`train.diffusion_loss`, on frames flattened to rows),
the training loop with its EMA and early stopping (`train.make_optimiser`,
`train.run_training_steps`, `stopping.EarlyStopping`), the DDIM
arithmetic (`sampling.predicted_x0_eps`, `sampling.ddim_step`, `sampling.ddim_timesteps`) and
which guidance passes run (`sampling_cells.guidance_passes`). Nothing is clipped: x0 is never clamped
and the frames come out in the target's units, so a bad model shows.

The frames are scaled to unit variance before diffusion (`data_scale`: 1 / the train frames'
std, stored with the weights) and scaled back after sampling, as latent diffusion scales its
latents (Rombach et al. 2022): the background-subtracted tactile frame is 0 almost everywhere
and its std is a few hundredths of the unit range, so unscaled, the noise swamps the signal at
all but the last few steps and a short training run learns to predict no contact.

Bit-reproducible on one machine: the initial weights come from torch.manual_seed(seed) inside
``torch.random.fork_rng`` (the caller's global RNG is left as it was), every random draw of
training (batches, timesteps, noise, condition drops) from one torch.Generator seeded with
`seed`, the validation draws from a second one seeded with seed + 1, and sampling's noise from
one numpy Generator seeded with its `seed`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from diffusers.models.unets.unet_2d import UNet2DModel
from torch import Tensor, nn

from tacgen_lib.generate.pixel.pixel_fit import PixelFit
from tacgen_lib.generate.pixel.settings import PixelDDPMSettings, frames_tensor
from tacgen_lib.generate.sampling import ddim_step, ddim_timesteps, predicted_x0_eps
from tacgen_lib.generate.sampling_cells import guidance_passes
from tacgen_lib.generate.schedules import Schedule, make_schedule
from tacgen_lib.generate.train import ValidationDraws, train_ema

__all__ = [
    "CURVE_COLUMNS",
    "PixelDDPMFit",
    "data_scale",
    "RowDenoiser",
    "fit_pixel_ddpm",
    "guided_unet_output",
    "make_unet",
    "sample_pixel_ddpm",
    "unet_output",
]

#: Columns of `PixelDDPMFit.curve`; row step 0 is the untrained model (train_loss NaN).
CURVE_COLUMNS = ("step", "train_loss", "val_loss")
#: Frames per forward pass when scoring the validation rows.
_VAL_BATCH = 256


def make_unet(settings: PixelDDPMSettings, size: Sequence[int]) -> UNet2DModel:
    """The denoiser: a diffusers ``UNet2DModel`` on 6 channels (noisy tactile x_t, then the
    RGB condition) to 3 (eps or v), ``block_out_channels`` = ``settings.channels`` with plain
    ResNet blocks (``DownBlock2D`` / ``UpBlock2D``; the mid block keeps diffusers' default
    self-attention), GroupNorm with 8 groups. Its weights are drawn from torch's global RNG.
    H and W must be multiples of 2 ** (len(channels) - 1)."""
    k = len(settings.channels)
    return UNet2DModel(
        sample_size=(int(size[0]), int(size[1])),
        in_channels=6,
        out_channels=3,
        block_out_channels=tuple(int(c) for c in settings.channels),
        layers_per_block=int(settings.layers_per_block),
        down_block_types=("DownBlock2D",) * k,
        up_block_types=("UpBlock2D",) * k,
        norm_num_groups=8,
    )


def data_scale(tac_train: Tensor | np.ndarray) -> float:
    """1 / std of the train tactile frames (all values): the factor that brings them to unit
    variance for diffusion; 1 for frames without contrast (all background)."""
    std = float(np.std(np.asarray(tac_train, dtype=np.float64)))
    if not np.isfinite(std):
        raise ValueError("data_scale: non-finite train frames")
    return 1.0 if std == 0.0 else 1.0 / std


def _divisor(unet: UNet2DModel) -> int:
    return 2 ** (len(unet.config.block_out_channels) - 1)


def unet_output(
    unet: UNet2DModel, x_t: Tensor, t: Tensor, rgb: Tensor, drop: Tensor | None
) -> Tensor:
    """The U-Net's eps or v for noisy tactile frames x_t (B, 3, H, W) at timesteps t (B,),
    given RGB frames (B, 3, H, W); rows with ``drop`` True see zeros instead of their RGB
    frame (the unconditional model of classifier-free guidance)."""
    if drop is not None:
        zero = torch.zeros((), dtype=rgb.dtype, device=rgb.device)
        rgb = torch.where(drop.view(-1, 1, 1, 1), zero, rgb)
    return unet(torch.cat([x_t, rgb], dim=1), t, return_dict=False)[0]


class RowDenoiser(nn.Module):
    """The U-Net as `train.diffusion_loss` calls a denoiser: frames flattened to rows
    (B, 3 H W), so the latent generator's loss applies unchanged."""

    def __init__(self, unet: UNet2DModel, size: tuple[int, int]) -> None:
        super().__init__()
        self.unet, self.shape = unet, (3, *size)

    def forward(self, x_t: Tensor, t: Tensor, cond: Tensor, drop: Tensor | None) -> Tensor:
        b = x_t.shape[0]
        out = unet_output(self.unet, x_t.view(b, *self.shape), t, cond.view(b, *self.shape), drop)
        return out.reshape(b, -1)


@dataclass(frozen=True, eq=False)
class PixelDDPMFit(PixelFit):
    """A trained pixel DDPM: its EMA U-Net (eval mode) and how it was trained (`PixelFit`;
    curve columns `CURVE_COLUMNS`, best_val a val loss). scale: `data_scale` of the train
    frames (the model denoises frames times scale; `sample_pixel_ddpm` divides it out).
    """

    scale: float = 1.0

    @property
    def schedule(self) -> Schedule:
        """The noise schedule the model was trained with (what sampling needs)."""
        return make_schedule(self.settings.schedule, self.settings.train_steps)


def _rows(
    rgb: np.ndarray, tac: np.ndarray, split: str, divisor: int, size: tuple[int, int] | None
) -> tuple[Tensor, Tensor, tuple[int, int]]:
    """(x0, cond) as rows (N, 3 H W) of one split, checked as frames first, and (H, W)."""
    c = frames_tensor(rgb, f"rgb_{split}", divisor=divisor)
    x = frames_tensor(tac, f"tac_{split}", divisor=divisor)
    if x.shape != c.shape:
        raise ValueError(
            f"{split}: RGB frames {tuple(c.shape)} and tactile frames {tuple(x.shape)} differ; "
            "row i of each must be one pair at one size"
        )
    hw = (int(x.shape[2]), int(x.shape[3]))
    if size is not None and x.shape[0] and hw != size:
        raise ValueError(f"{split}: frame size {hw} differs from train's {size}")
    return x.reshape(x.shape[0], -1), c.reshape(c.shape[0], -1), hw


def _val_loss(ema_rows: nn.Module, draws: ValidationDraws) -> float:
    """The mean loss over every val row and repeat, scored `_VAL_BATCH` rows at a time (NaN
    without val rows)."""
    n_va = draws.x.shape[0]
    if n_va == 0:
        return math.nan
    ema_rows.eval()
    repeats = draws.t.shape[0]
    total = 0.0
    with torch.no_grad():
        for r in range(repeats):
            for s in range(0, n_va, _VAL_BATCH):
                rows = slice(s, s + _VAL_BATCH)
                total += draws.loss(ema_rows, r, rows).item() * draws.x[rows].shape[0]
    return total / (repeats * n_va)


def fit_pixel_ddpm(
    rgb_train: np.ndarray,
    tac_train: np.ndarray,
    rgb_val: np.ndarray,
    tac_val: np.ndarray,
    settings: PixelDDPMSettings,
    seed: int,
    progress: Callable[[str], Any] | None = None,
    *,
    device: torch.device | str,
) -> PixelDDPMFit:
    """Train the eps- (or v-) prediction U-Net on train pairs, early-stopped on val pairs.

    The latent generator's training (`train.train_ema`): a minibatch of ``batch_size`` pairs
    drawn with replacement, t uniform in 0..T-1, eps ~ N(0, I), the RGB condition dropped with
    probability ``p_uncond``; the denoising loss (`train.diffusion_loss`, DDPM eq. 14 or
    its v-target), fused AdamW, then the EMA. Every ``eval_every`` steps (and at the last)
    the EMA model's loss on the val pairs at fixed (t, noise) draws; the best EMA weights are
    kept, and training stops after ``patience`` evaluations without improvement (0: never).

    device: where it trains (`tacgen_lib.runtime.device`): the U-Net initialised and every
    random draw made on the CPU, then moved (on the CPU no move); the EMA U-Net comes back on
    the CPU.
    """
    say = progress or (lambda _m: None)
    divisor = 2 ** (len(settings.channels) - 1)
    x_tr, c_tr, size = _rows(rgb_train, tac_train, "train", divisor, None)
    if x_tr.shape[0] < 1:
        raise ValueError("fit_pixel_ddpm: no train pairs")
    x_va, c_va, _ = _rows(rgb_val, tac_val, "val", divisor, size)
    scale = data_scale(x_tr)
    x_tr, x_va = x_tr * scale, x_va * scale
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        unet = make_unet(settings, size)
    rows = lambda m: RowDenoiser(m, size)  # noqa: E731 (the U-Net as diffusion_loss calls it)
    data = (x_tr, c_tr), (x_va, c_va)
    fit = train_ema(
        unet,
        *data,
        settings,
        seed,
        device,
        val_loss=_val_loss,
        wrap=rows,
        score_untrained=True,
        progress=say,
    )
    return PixelDDPMFit.from_training(
        fit.ema,
        fit.stopper,
        fit.curve,
        CURVE_COLUMNS,
        settings=settings,
        seed=seed,
        size=size,
        steps_run=fit.steps_run,
        scale=scale,
    )


def guided_unet_output(
    unet: UNet2DModel, x_t: np.ndarray, t: int, rgb: np.ndarray, guidance: float
) -> np.ndarray:
    """Classifier-free guidance at one timestep: out_u + w (out_c - out_u) (Ho & Salimans).

    Only the passes `sampling_cells.guidance_passes` names run: the conditional pass alone at w = 1
    (exactly out_c), the unconditional alone at w = 0 (exactly out_u), else both in one batch
    of 2B. x_t, rgb: (B, 3, H, W) float32; returns float32 (B, 3, H, W). Runs on the U-Net's
    device (on the CPU no move).
    """
    passes = guidance_passes(guidance)
    b = x_t.shape[0]
    k = len(passes)
    dev = next(unet.parameters()).device
    x = torch.from_numpy(np.ascontiguousarray(x_t, dtype=np.float32)).to(dev)
    c = torch.from_numpy(np.ascontiguousarray(rgb, dtype=np.float32)).to(dev)
    drop = torch.tensor(passes, dtype=torch.bool).repeat_interleave(b).to(dev)
    with torch.inference_mode():
        out = (
            unet_output(
                unet,
                torch.cat([x] * k) if k > 1 else x,
                torch.full((k * b,), int(t), dtype=torch.long).to(dev),
                torch.cat([c] * k) if k > 1 else c,
                drop,
            )
            .cpu()
            .numpy()
        )
    if k == 1:
        return out
    out_c, out_u = out[:b], out[b:]
    return out_u + np.float32(guidance) * (out_c - out_u)


def sample_pixel_ddpm(
    model: UNet2DModel,
    rgb: np.ndarray,
    *,
    schedule: Schedule,
    prediction: str,
    steps: int,
    guidance: float,
    eta: float,
    seed: int,
    batch: int,
    scale: float = 1.0,
) -> np.ndarray:
    """Tactile frames (N, 3, H, W) float32 for RGB frames (N, 3, H, W): DDIM (Song et al.
    2021) over `ddim_timesteps(T, steps)` with classifier-free guidance `guidance`, divided by
    the model's data `scale` (`PixelDDPMFit.scale`) at the end.

    1. x_T ~ N(0, I) for all N frames at once, from numpy's PCG64 seeded with `seed`
    2. per DDIM step, for each run of `batch` frames: the guided output
       (`guided_unet_output`), then (x0, eps) (`predicted_x0_eps`, no clipping)
    3. x_{t_prev} by `ddim_step` (eta > 0: its noise for all N frames drawn per step)

    All draws cover the whole (N, 3, H, W) array in one order, so `batch` changes the result
    only through float rounding of the U-Net's batched kernels. The model runs in eval mode
    under ``torch.inference_mode``; the alpha-bars stay float64 as in `sampling.sample`.
    """
    cond = frames_tensor(rgb, "rgb", divisor=_divisor(model)).numpy()
    if batch < 1:
        raise ValueError(f"batch must be >= 1, got {batch}")
    model.eval()
    T = schedule.n_steps
    ts = ddim_timesteps(T, steps)
    abar64 = schedule.alphas_cumprod
    sqrt_abar = np.sqrt(abar64).astype(np.float32)
    sqrt_1m = np.sqrt(schedule.one_minus_alphas_cumprod).astype(np.float32)
    rng = np.random.default_rng(int(seed))
    x = rng.standard_normal(cond.shape, dtype=np.float32)
    for i, t in enumerate(ts):
        t = int(t)
        t_prev = int(ts[i + 1]) if i + 1 < len(ts) else -1
        abar_prev = float(abar64[t_prev]) if t_prev >= 0 else 1.0
        draw = eta > 0 and t_prev >= 0
        noise = rng.standard_normal(x.shape, dtype=np.float32) if draw else None
        x_next = np.empty_like(x)
        for s in range(0, x.shape[0], batch):
            rows = slice(s, s + batch)
            out = guided_unet_output(model, x[rows], t, cond[rows], guidance)
            x0, eps = predicted_x0_eps(out, x[rows], sqrt_abar[t], sqrt_1m[t], prediction)
            x_next[rows] = ddim_step(
                x0, eps, float(abar64[t]), abar_prev, eta, None if noise is None else noise[rows]
            )
        x = x_next
    return x / np.float32(scale)
