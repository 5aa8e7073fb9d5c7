"""DINO's multi-crop augmentation: seeded random resized crops (global and local) with colour
jitter, drawn from a torch Generator so a pretraining run is bit-for-bit reproducible.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor

from tacgen_lib.features.extract import imagenet_normalise


def random_resized_crop(
    x: Tensor, size: int, scale: tuple[float, float], gen: torch.Generator
) -> Tensor:
    """Per-image random resized crop (area fraction in `scale`, aspect 3/4..4/3) + h-flip."""
    b = x.shape[0]
    u = torch.rand(b, 6, generator=gen, dtype=torch.float64)
    area = scale[0] + (scale[1] - scale[0]) * u[:, 0]
    log_ratio = math.log(3 / 4) + (math.log(4 / 3) - math.log(3 / 4)) * u[:, 1]
    ratio = torch.exp(log_ratio)
    cw = torch.sqrt(area * ratio).clamp(max=1.0)  # crop width / image width
    ch = torch.sqrt(area / ratio).clamp(max=1.0)
    cx = (1 - cw) * (2 * u[:, 2] - 1)  # crop centre in [-1, 1] coordinates
    cy = (1 - ch) * (2 * u[:, 3] - 1)
    flip = torch.where(u[:, 4] < 0.5, -1.0, 1.0).to(torch.float64)
    theta = torch.zeros(b, 2, 3, dtype=torch.float64)
    theta[:, 0, 0] = cw * flip
    theta[:, 0, 2] = cx
    theta[:, 1, 1] = ch
    theta[:, 1, 2] = cy
    grid = F.affine_grid(theta.to(x.dtype), [b, 3, size, size], align_corners=False)
    return F.grid_sample(x, grid, mode="bilinear", padding_mode="reflection", align_corners=False)


def _colour_jitter(x: Tensor, gen: torch.Generator, strength: float) -> Tensor:
    """Brightness, contrast, saturation jitter (p=0.8) then random greyscale (p=0.2)."""
    b = x.shape[0]
    u = torch.rand(b, 5, generator=gen)
    on = (u[:, 0] < 0.8).view(b, 1, 1, 1)
    bright = (1 + strength * (2 * u[:, 1] - 1)).view(b, 1, 1, 1)
    contrast = (1 + strength * (2 * u[:, 2] - 1)).view(b, 1, 1, 1)
    sat = (1 + strength * (2 * u[:, 3] - 1)).view(b, 1, 1, 1)
    lum_w = torch.tensor([0.299, 0.587, 0.114], dtype=x.dtype).view(1, 3, 1, 1)
    y = (x * bright).clamp(0, 1)
    mean = (y * lum_w).sum(1, keepdim=True).mean((2, 3), keepdim=True)
    y = ((y - mean) * contrast + mean).clamp(0, 1)
    grey = (y * lum_w).sum(1, keepdim=True)
    y = ((y - grey) * sat + grey).clamp(0, 1)
    y = torch.where(on, y, x)
    to_grey = (u[:, 4] < 0.2).view(b, 1, 1, 1)
    return torch.where(to_grey, (y * lum_w).sum(1, keepdim=True).expand_as(y), y)


def multi_crop(
    x: Tensor,
    gen: torch.Generator,
    *,
    global_size: int,
    local_size: int,
    n_local: int,
    jitter: float,
    global_scale: tuple[float, float] = (0.4, 1.0),
    local_scale: tuple[float, float] = (0.05, 0.4),
) -> list[Tensor]:
    """DINO multi-crop of a batch (B, 3, H, W) in [0, 1]: 2 global then n_local local views.

    Each view is ImageNet-normalised and ready for the backbone.
    """
    views = []
    for i in range(2 + n_local):
        size, scale = (global_size, global_scale) if i < 2 else (local_size, local_scale)
        v = _colour_jitter(random_resized_crop(x, size, scale, gen), gen, jitter)
        views.append(imagenet_normalise(v))
    return views
