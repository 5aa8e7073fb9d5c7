"""The pixel generators' settings (one frozen object per model, from config ``pixel``) and the
frame contract both models check.

`Pix2PixSettings.from_config(config["pixel"]["pix2pix"])` and
`PixelDDPMSettings.from_config(config["pixel"]["ddpm"])` read what training and sampling need
(the schema has already checked types); `tiny()` is a seconds-long budget for tests.
`frames_tensor` checks one array of frames (float32 NCHW, 3 channels, finite, H and W
divisible by what the model's down-sampling needs) and views it as a torch tensor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
import torch
from torch import Tensor

from tacgen_lib.io.config import settings_from

__all__ = ["PixelDDPMSettings", "Pix2PixSettings", "frames_tensor"]


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


def _check_ints(where: str, obj: object, names: tuple[tuple[str, int], ...]) -> None:
    for name, low in names:
        value = getattr(obj, name)
        if isinstance(value, bool) or int(value) != value or value < low:
            raise ValueError(f"{where}.{name} must be an integer >= {low}, got {value!r}")


def _check_widths(where: str, name: str, widths: tuple[int, ...], multiple: int = 1) -> None:
    if not widths or any(int(c) != c or c < 1 or c % multiple for c in widths):
        what = f"positive multiples of {multiple}" if multiple > 1 else "positive integers"
        raise ValueError(f"{where}.{name} must be a non-empty list of {what}, got {widths!r}")


def _check_range(where: str, obj: object, names: tuple[tuple[str, float, float], ...]) -> None:
    for name, lo, hi in names:
        value = getattr(obj, name)
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ValueError(f"{where}.{name} must be in [{lo}, {hi}], got {value!r}")


@dataclass(frozen=True)
class Pix2PixSettings:
    """How one pix2pix translator is trained (`pix2pix.fit_pix2pix`; Isola et al. 2017).

    Model: a U-Net whose encoder widths are ``channels`` (the decoder mirrors them), decoder
    ``dropout`` on its innermost layers (train mode only), and a conditional PatchGAN whose
    stride-2 widths are ``disc_channels``. Objective: GAN loss + ``lambda_l1`` x L1 (paper
    eq. 4, lambda = 100). Training: Adam (``lr``, betas (``beta1``, 0.999)) for both nets,
    ``batch_size`` frames, at most ``steps`` steps, validation L1 every ``eval_every`` steps
    with early stopping after ``patience`` evaluations without improvement (0: never stop).
    """

    channels: tuple[int, ...] = (32, 64, 128)
    disc_channels: tuple[int, ...] = (32, 64)
    dropout: float = 0.5
    lambda_l1: float = 100.0
    lr: float = 2e-4
    beta1: float = 0.5
    batch_size: int = 32
    steps: int = 600
    eval_every: int = 100
    patience: int = 3

    def __post_init__(self) -> None:
        where = "pixel.pix2pix"
        _check_widths(where, "channels", self.channels)
        _check_widths(where, "disc_channels", self.disc_channels)
        _check_ints(
            where,
            self,
            (("batch_size", 1), ("steps", 1), ("eval_every", 1), ("patience", 0)),
        )
        _check_range(where, self, (("dropout", 0.0, 0.99), ("beta1", 0.0, 0.999)))
        for name in ("lambda_l1", "lr"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{where}.{name} must be a finite number >= 0, got {value!r}")

    @classmethod
    def from_config(cls, section: Mapping[str, Any]) -> Pix2PixSettings:
        """Settings from config ``pixel.pix2pix``."""
        return settings_from(cls, section, where="pixel.pix2pix")

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
class PixelDDPMSettings:
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

    channels: tuple[int, ...] = (16, 32, 32)
    layers_per_block: int = 1
    schedule: Literal["cosine", "linear"] = "cosine"
    train_steps: int = 1000
    prediction: Literal["eps", "v"] = "v"
    p_uncond: float = 0.1
    lr: float = 1e-3
    weight_decay: float = 0.01
    batch_size: int = 32
    steps: int = 600
    ema_decay: float = 0.99
    eval_every: int = 100
    patience: int = 3
    eta: float = 0.0

    def __post_init__(self) -> None:
        where = "pixel.ddpm"
        _check_widths(where, "channels", self.channels, multiple=8)
        if self.schedule not in ("cosine", "linear"):
            raise ValueError(
                f"{where}.schedule must be 'cosine' or 'linear', got {self.schedule!r}"
            )
        if self.prediction not in ("eps", "v"):
            raise ValueError(f"{where}.prediction must be 'eps' or 'v', got {self.prediction!r}")
        _check_ints(
            where,
            self,
            (
                ("layers_per_block", 1),
                ("train_steps", 2),
                ("batch_size", 1),
                ("steps", 1),
                ("eval_every", 1),
                ("patience", 0),
            ),
        )
        _check_range(
            where, self, (("p_uncond", 0.0, 1.0), ("ema_decay", 0.0, 1.0), ("eta", 0.0, 1.0))
        )
        for name in ("lr", "weight_decay"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{where}.{name} must be a finite number >= 0, got {value!r}")

    @property
    def clip_grad(self) -> float:
        """0: `train.training_step` (which this model's training reuses) clips no gradient."""
        return 0.0

    @classmethod
    def from_config(cls, section: Mapping[str, Any]) -> PixelDDPMSettings:
        """Settings from config ``pixel.ddpm``."""
        return settings_from(cls, section, where="pixel.ddpm")

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
