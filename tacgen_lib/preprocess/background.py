"""Tactile background subtraction (paper: `tactile_proc`) and its ablation variants.

A tactile frame is the sensor's gel image under contact; the background is the same sensor's
frame without contact. The paper's canonical preprocessing subtracts the background and
re-centres on mid-grey, so "no contact" is 128 everywhere and the contact signal is the
deviation from 128. The ablation variants, selected by name in `background_subtract`:

    clip128    clip(tactile - background + 128, 0, 255)          (canonical, = tactile_proc)
    histmatch  background histogram-matched to the frame per channel, then clip128
    residual   signed residual r = tactile - background in [-255, 255], mapped to uint8 by the
               fixed affine map (r + 256) // 2 (no clipping: 0 -> 128, -255 -> 0, 255 -> 255)
    clahe      CLAHE on the L channel (LAB) of the raw frame, no subtraction
    none       the raw frame

All inputs are uint8 RGB (H, W, 3) and outputs are uint8 RGB of the same shape.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = [
    "VARIANTS",
    "tactile_proc",
    "histogram_match",
    "residual_proc",
    "clahe_proc",
    "background_subtract",
]

VARIANTS: tuple[str, ...] = ("clip128", "histmatch", "residual", "clahe", "none")

# CLAHE settings of the "clahe" variant (OpenCV defaults for tile grid, moderate clip limit).
CLAHE_CLIP_LIMIT = 2.0
CLAHE_TILE_GRID = (8, 8)


def _check_rgb(image: np.ndarray, name: str) -> None:
    if not isinstance(image, np.ndarray):
        raise TypeError(f"{name}: expected a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise TypeError(f"{name}: expected uint8 pixels, got {image.dtype}; pass raw frames")
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"{name}: expected shape (H, W, 3), got {image.shape}")


def _check_pair(tactile: np.ndarray, background: np.ndarray) -> None:
    _check_rgb(tactile, "tactile")
    _check_rgb(background, "background")
    if tactile.shape != background.shape:
        raise ValueError(
            f"tactile frame {tactile.shape} and background {background.shape} differ in shape; "
            "use the background image of the same sensor at the same resolution"
        )


def tactile_proc(tactile: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Background subtraction of the paper: clip(tactile - background + 128, 0, 255) as uint8.

    Computed in int16, so there is no uint8 wraparound.
    """
    _check_pair(tactile, background)
    diff = tactile.astype(np.int16) - background.astype(np.int16) + 128
    return np.clip(diff, 0, 255).astype(np.uint8)


def histogram_match(source: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Per-channel histogram matching of `source` to `template` (uint8 RGB, any sizes).

    Each source value is sent to the template value at the same cumulative quantile (linear
    interpolation between the template's distinct values, as scikit-image's match_histograms),
    rounded to the nearest integer. When source == template the map is the identity.
    """
    _check_rgb(source, "source")
    _check_rgb(template, "template")
    out = np.empty_like(source)
    for c in range(3):
        src = source[:, :, c].ravel()
        src_values, src_idx, src_counts = np.unique(src, return_inverse=True, return_counts=True)
        tmpl_values, tmpl_counts = np.unique(template[:, :, c], return_counts=True)
        src_q = np.cumsum(src_counts) / src.size
        tmpl_q = np.cumsum(tmpl_counts) / template[:, :, c].size
        mapped = np.interp(src_q, tmpl_q, tmpl_values.astype(np.float64))
        lut = np.clip(np.rint(mapped), 0, 255).astype(np.uint8)
        out[:, :, c] = lut[src_idx].reshape(source.shape[:2])
    return out


def residual_proc(tactile: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Signed residual without clipping, as uint8 by the fixed map (tactile - background + 256) // 2.

    The map is the same for every sample (so values stay comparable across samples) and
    covers the whole residual range [-255, 255] -> [0, 255] at half resolution; 0 -> 128.
    """
    _check_pair(tactile, background)
    r = tactile.astype(np.int16) - background.astype(np.int16)
    return ((r + 256) // 2).astype(np.uint8)


def clahe_proc(tactile: np.ndarray) -> np.ndarray:
    """CLAHE (clip limit 2.0, 8x8 tiles) on the L channel of the frame in LAB; a, b untouched."""
    _check_rgb(tactile, "tactile")
    lab = cv2.cvtColor(np.ascontiguousarray(tactile), cv2.COLOR_RGB2LAB)
    clahe = cv2.createCLAHE(clipLimit=CLAHE_CLIP_LIMIT, tileGridSize=CLAHE_TILE_GRID)
    lab[:, :, 0] = clahe.apply(np.ascontiguousarray(lab[:, :, 0]))
    return cv2.cvtColor(lab, cv2.COLOR_LAB2RGB)


def background_subtract(tactile: np.ndarray, background: np.ndarray, variant: str) -> np.ndarray:
    """Apply one preprocessing variant (see the module docstring) to a tactile frame.

    The background is validated for every variant (same shape, uint8 RGB), even those that do
    not use it ("clahe", "none"), so a wrong pairing fails the same way everywhere.
    """
    if variant not in VARIANTS:
        raise ValueError(f"unknown background-subtraction variant {variant!r}; valid: {VARIANTS}")
    _check_pair(tactile, background)
    if variant == "clip128":
        return tactile_proc(tactile, background)
    if variant == "histmatch":
        return tactile_proc(tactile, histogram_match(background, tactile))
    if variant == "residual":
        return residual_proc(tactile, background)
    if variant == "clahe":
        return clahe_proc(tactile)
    return tactile.copy()
