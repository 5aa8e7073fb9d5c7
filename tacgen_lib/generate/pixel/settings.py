"""The pixel generators' settings (one frozen object per model, from config ``pixel``) and the
frame contract both models check.

`Pix2PixSettings.from_config(config["pixel"]["pix2pix"])` and
`PixelDDPMSettings.from_config(config["pixel"]["ddpm"])` read what training and sampling need
(each field's default and bounds are its key's in config/config.schema.yaml); `tiny()` is a seconds-long budget for tests.
`frames_tensor` checks one array of frames (float32 NCHW, 3 channels, finite, H and W
divisible by what the model's down-sampling needs) and views it as a torch tensor.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import torch
from torch import Tensor

from tacgen_lib.io.config import settings_from
from tacgen_lib.io.schema import SchemaSettings, schema_fields, setting

__all__ = ["PixelDDPMSettings", "PixelSettings", "Pix2PixSettings", "frames_tensor"]


def frames_tensor(x: np.ndarray, name: str, *, divisor: int = 1) -> Tensor:
    """`x` as a float32 torch tensor (N, 3, H, W), refusing what no model can take.

    Frames: RGB in [-1, 1] or tactile as (x - 128) / 128; N may be 0 or 1. `divisor`: what H
    and W must be multiples of (2 ** number of stride-2 levels of the model). The values are
    not range-checked (a generator's output is never clipped either), only for finiteness.
    """
    arr = np.asarray(x)
    if arr.ndim != 4 or arr.shape[1] != 3:
        raise ValueError(f"{name}: expected frames of shape (N, 3, H, W), got shape {arr.shape}")
    h, w = arr.shape[2:]
    if h < divisor or w < divisor or h % divisor or w % divisor:
        raise ValueError(
            f"{name}: frame size {h}x{w} must be a positive multiple of {divisor} in both "
            "dimensions (2 ** the model's stride-2 levels); resize the frames or use fewer levels"
        )
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    if not arr.flags.writeable:  # torch.from_numpy warns on read-only memory (a memory map)
        arr = arr.copy()
    if not np.isfinite(arr).all():
        bad = int(np.argwhere(~np.isfinite(arr))[0][0])
        raise ValueError(f"{name}: frame {bad} has NaN or infinite values")
    return torch.from_numpy(arr)


@dataclass(frozen=True)
@schema_fields("pixel.pix2pix")
class Pix2PixSettings(SchemaSettings):
    """How one pix2pix translator is trained (`pix2pix.fit_pix2pix`; Isola et al. 2017).

    Model: a U-Net whose encoder widths are ``channels`` (the decoder mirrors them), decoder
    ``dropout`` on its innermost layers (train mode only), and a conditional PatchGAN whose
    stride-2 widths are ``disc_channels``. Objective: GAN loss + ``lambda_l1`` x L1 (paper
    eq. 4, lambda = 100). Training: Adam (``lr``, betas (``beta1``, 0.999)) for both nets,
    ``batch_size`` frames, at most ``steps`` steps, validation L1 every ``eval_every`` steps
    with early stopping after ``patience`` evaluations without improvement (0: never stop).
    """

    @classmethod
    def tiny(cls, **changes: Any) -> Pix2PixSettings:
        """A model and budget that train in about a second, for tests; `changes` override."""
        small = cls(
            channels=(8, 16),
            disc_channels=(8, 16),
            batch_size=8,
            steps=40,
            eval_every=10,
            patience=0,
            lr=2e-3,
        )
        return replace(small, **changes)


@dataclass(frozen=True)
@schema_fields("pixel.ddpm")
class PixelDDPMSettings(SchemaSettings):
    """How one pixel DDPM is trained (`ddpm.fit_pixel_ddpm`) and sampled.

    Model: a diffusers ``UNet2DModel`` with ``block_out_channels`` = ``channels`` (multiples
    of 8: GroupNorm with 8 groups) and ``layers_per_block`` ResNet blocks per level, on
    concat(x_t, RGB); eps- or v-``prediction``; a ``schedule`` (cosine | linear) of
    ``train_steps`` = T steps; the RGB condition dropped (zeros) with probability
    ``p_uncond`` for classifier-free guidance. Training: AdamW (``lr``, ``weight_decay``),
    ``batch_size`` frames, at most ``steps`` steps, EMA of the weights with ``ema_decay``,
    validation loss every ``eval_every`` steps, early stopping after ``patience`` evaluations
    without improvement (0: never stop). Sampling: DDIM's ``eta`` (0 = deterministic).
    No gradient clipping (`clip_grad` is 0 and not a config key).
    """

    @property
    def clip_grad(self) -> float:
        """0: `train.training_step` (which this model's training reuses) clips no gradient."""
        return 0.0

    @classmethod
    def tiny(cls, **changes: Any) -> PixelDDPMSettings:
        """A model and budget that train in about a second, for tests; `changes` override."""
        small = cls(
            channels=(8, 16),
            train_steps=100,
            batch_size=8,
            steps=40,
            eval_every=10,
            patience=0,
            ema_decay=0.8,
            lr=2e-3,
        )
        return replace(small, **changes)


@dataclass(frozen=True)
@schema_fields("pixel", skip=("corpora", "seeds", "ddpm_cells", "curve", "pix2pix", "ddpm"))
class PixelSettings(SchemaSettings):
    """The pixel stage's settings (config ``pixel``; its grids, corpora, seeds, DDPM cells and
    the curve, are the rules'): the generated frame `size` (H, W), `batch` frames per sampling
    batch, `bootstrap` resamples of the reconstruction CIs, and each model's settings."""

    pix2pix: Pix2PixSettings = setting("pixel.pix2pix", default_factory=Pix2PixSettings)
    ddpm: PixelDDPMSettings = setting("pixel.ddpm", default_factory=PixelDDPMSettings)

    @classmethod
    def from_config(cls, pixel: Mapping[str, Any]) -> PixelSettings:
        """Settings from config ``pixel``."""
        return settings_from(
            cls,
            pixel,
            where="pixel",
            pix2pix=Pix2PixSettings.from_config(pixel.get("pix2pix") or {}),
            ddpm=PixelDDPMSettings.from_config(pixel.get("ddpm") or {}),
        )
