"""Frozen-feature extraction: ViT features (CLS or mean patch token) and the "pixel-V" baseline.

This module owns how uint8 frames become model inputs (resize to a square of `image_size`
pixels with antialiased bilinear interpolation, scale to [0, 1], ImageNet mean/std
normalisation) and how model outputs become one float32 vector per frame. The same input
pipeline is used by DINO pretraining (tacgen_lib.features.dino), so features and pretraining agree.

Non-square frames are resized (not cropped) to the square input, so the whole gel / view is
kept; the aspect change is the same for every frame of a modality.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

if TYPE_CHECKING:
    from tacgen_lib.features.settings import FeatureSettings

__all__ = [
    "POOLS",
    "IMAGENET_MEAN",
    "IMAGENET_STD",
    "check_train_frames",
    "imagenet_normalise",
    "to_unit_tensor",
    "extract_features",
    "feature_width",
    "pixel_features",
]

#: How a frame's feature is read from a backbone (`extract_features`).
POOLS = ("cls", "mean_patch", "stages")

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def _check_images(images: np.ndarray, where: str) -> None:
    if not isinstance(images, np.ndarray) or images.dtype != np.uint8:
        got = images.dtype if isinstance(images, np.ndarray) else type(images).__name__
        raise TypeError(f"{where}: expected a uint8 array (N, H, W, 3), got {got}")
    if images.ndim != 4 or images.shape[3] != 3:
        raise ValueError(f"{where}: expected shape (N, H, W, 3), got {images.shape}")


def check_train_frames(images: np.ndarray, where: str) -> None:
    """Refuse pretraining frames that are not uint8 (N, H, W, 3): a ValueError naming `where`
    (the pretraining function), the dtype and the shape."""
    if images.ndim != 4 or images.shape[3] != 3 or images.dtype != np.uint8:
        raise ValueError(
            f"{where}: expected uint8 frames (N, H, W, 3), got {images.dtype} {images.shape}"
        )


def imagenet_normalise(x: Tensor) -> Tensor:
    """(x - mean) / std per channel for (B, 3, H, W) images in [0, 1]."""
    mean = torch.tensor(IMAGENET_MEAN, dtype=x.dtype).view(1, 3, 1, 1)
    std = torch.tensor(IMAGENET_STD, dtype=x.dtype).view(1, 3, 1, 1)
    return (x - mean) / std


def to_unit_tensor(images: np.ndarray, image_size: int) -> Tensor:
    """uint8 (N, H, W, 3) -> float32 (N, 3, S, S) in [0, 1], antialiased bilinear resize."""
    _check_images(images, "to_unit_tensor")
    x = torch.from_numpy(np.ascontiguousarray(images)).permute(0, 3, 1, 2).float() / 255.0
    if x.shape[2:] != (image_size, image_size):
        x = F.interpolate(
            x, size=(image_size, image_size), mode="bilinear", antialias=True, align_corners=False
        ).clamp_(0.0, 1.0)
    return x


def extract_features(
    model: nn.Module,
    images: np.ndarray,
    *,
    image_size: int,
    batch_size: int,
    pool: Literal["cls", "mean_patch", "stages"],
    device: torch.device | str,
) -> np.ndarray:
    """Frozen backbone features, one float32 row per frame: (N, `feature_width(model, pool)`).

    `model` is a ViT (`vit.DinoVisionTransformer`) or a ResNet (`resnet.ResNet`, whose "cls"
    and "mean_patch" pools both give its global average; `patch_size` 1).

    pool="cls" takes the normalised CLS token (x_norm_clstoken); "mean_patch" averages the
    normalised patch tokens (x_norm_patchtokens); "stages" (a ResNet only) reads the last
    stage's mean beside the std over space of the earlier stages' maps
    (`resnet.ResNet.stage_statistics`). Runs under torch.inference_mode with the model
    in eval mode (its training flag is restored afterwards). Deterministic: the same weights,
    images and batch_size give identical bytes on the same machine/torch build.

    device: where the backbone runs (`tacgen_lib.runtime.device`; it is moved there and back).
    Frames are resized and normalised on the CPU either way, then moved: on the CPU no move.
    """
    _check_images(images, "extract_features")
    width = feature_width(model, pool)
    if image_size % model.patch_size:
        raise ValueError(
            f"extract_features: image_size {image_size} is not a multiple of the patch size "
            f"{model.patch_size}"
        )
    if batch_size < 1:
        raise ValueError(f"extract_features: batch_size must be >= 1, got {batch_size}")
    out = np.empty((images.shape[0], width), dtype=np.float32)
    was_training = model.training
    home = next(model.parameters()).device
    dev = torch.device(device)
    model.to(dev)
    model.eval()
    try:
        with torch.inference_mode():
            for start in range(0, images.shape[0], batch_size):
                x = imagenet_normalise(
                    to_unit_tensor(images[start : start + batch_size], image_size)
                ).to(dev)
                if pool == "stages":
                    z = model.stage_statistics(x)
                elif pool == "cls":
                    z = model.forward_features(x)["x_norm_clstoken"]
                else:
                    z = model.forward_features(x)["x_norm_patchtokens"].mean(dim=1)
                out[start : start + z.shape[0]] = z.float().cpu().numpy()
    finally:
        model.train(was_training)
        model.to(home)
    return out


def feature_width(model: nn.Module, pool: str) -> int:
    """Width of the feature `extract_features` reads from `model` with `pool`. Raises
    ValueError for an unknown pool or "stages" on a model without `stage_statistics` (a
    ViT)."""
    if pool not in POOLS:
        raise ValueError(f"extract_features: pool must be one of {POOLS}, got {pool!r}")
    if pool != "stages":
        return int(model.embed_dim)
    if not hasattr(model, "stage_statistics"):
        raise ValueError(
            f"extract_features: pool 'stages' needs a ResNet, got {type(model).__name__}"
        )
    return int(model.stage_statistics_dim)


def extract_with(
    model: nn.Module,
    images: np.ndarray,
    settings: FeatureSettings,
    *,
    device: torch.device | str,
) -> np.ndarray:
    """`extract_features` at the config's image size, batch and pool (config ``features``)."""
    return extract_features(
        model,
        images,
        image_size=settings.image_size,
        batch_size=settings.batch_size,
        pool=settings.pool,
        device=device,
    )


def pixel_features(images: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """ "pixel-V" baseline: frames downsampled to size = (height, width) (config
    ``features.pixel_size``) with area interpolation, scaled to [0, 1] and flattened (row-major
    H, W, RGB): float32 (N, height * width * 3)."""
    _check_images(images, "pixel_features")
    h, w = size
    if h < 1 or w < 1:
        raise ValueError(f"pixel_features: size must be positive, got {size}")
    out = np.empty((images.shape[0], h * w * 3), dtype=np.float32)
    for i, img in enumerate(images):
        small = cv2.resize(np.ascontiguousarray(img), (w, h), interpolation=cv2.INTER_AREA)
        out[i] = small.reshape(-1).astype(np.float32) / np.float32(255.0)
    return out
