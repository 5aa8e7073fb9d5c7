"""Reconstruction of generated tactile frames, and the gain calibration of their contrast.

Reconstruction is one axis of a pixel generator; utility (what its frames add to the probes
through the frozen tactile ViT) is the other, and the paper's point is that they rank
generators differently. Per test row, on the uint8 clip128 frames the ViT reads, both at the
generators' frame size:

- ``pixel_l2``: root-mean-square difference with frames scaled to [0, 1] (x / 255);
- ``ssim``: `skimage.metrics.structural_similarity` (Wang et al. 2004: 7 x 7 uniform window,
  ``data_range`` 255, the three channels averaged);
- a perceptual distance: LPIPS needs ImageNet-trained VGG/AlexNet weights that cannot be
  downloaded here. The stand-in is the frozen tactile ViT's own distance (the generator
  evaluation's matched-pair cosine), stated as such wherever it is shown.

Texture and contrast, as the paper's calibration step measures them (ratios of generated to
real over a set of frames, in tactile units where the background is 0):

- ``std_ratio``: std(generated) / std(real);
- ``highpass_ratio``: the energy of the 3 x 3 Laplacian (`scipy.ndimage.laplace`, mirrored borders)
  of generated over that of real frames: fine texture, which a blurry generator lacks.

`fit_gain` is the calibration: one scalar g with std(g x_gen) = std(x_real) on TRAIN rows (it
scales contrast about the background, which stays 0); applied unchanged to every row. It is
never chosen on test rows.
"""

from __future__ import annotations

import numpy as np
from skimage.metrics import structural_similarity

__all__ = [
    "RECONSTRUCTION_COLUMNS",
    "fit_gain",
    "highpass_energy",
    "mean_interval",
    "pixel_l2",
    "reconstruction_row",
    "ssim",
    "std_ratio",
    "highpass_ratio",
]


def _pair(real: np.ndarray, gen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    real, gen = np.asarray(real), np.asarray(gen)
    if real.shape != gen.shape or real.ndim != 4 or real.shape[-1] != 3:
        raise ValueError(
            f"reconstruction: real {real.shape} and generated {gen.shape} frames must both be "
            "(N, H, W, 3)"
        )
    if real.dtype != np.uint8 or gen.dtype != np.uint8:
        raise ValueError("reconstruction: frames must be uint8 (what the tactile ViT reads)")
    return real, gen


def pixel_l2(real: np.ndarray, gen: np.ndarray) -> np.ndarray:
    """Per frame: RMS difference of the (N, H, W, 3) uint8 frames scaled to [0, 1]."""
    real, gen = _pair(real, gen)
    d = (real.astype(np.float64) - gen.astype(np.float64)) / 255.0
    return np.sqrt(np.mean(d**2, axis=(1, 2, 3)))


def ssim(real: np.ndarray, gen: np.ndarray) -> np.ndarray:
    """Per frame: SSIM of the (N, H, W, 3) uint8 frames (skimage, channels averaged)."""
    real, gen = _pair(real, gen)
    return np.array(
        [
            structural_similarity(r, g, channel_axis=-1, data_range=255)
            for r, g in zip(real, gen, strict=True)
        ],
        dtype=np.float64,
    )


def highpass_energy(x: np.ndarray) -> float:
    """Mean squared 3 x 3 Laplacian of (N, 3, H, W) frames in tactile units (float64, mirrored
    borders)."""
    from scipy.ndimage import laplace

    x = np.asarray(x, dtype=np.float64)
    total = 0.0
    for frame in x.reshape(-1, *x.shape[-2:]):
        total += float(np.sum(laplace(frame, mode="mirror") ** 2))
    return total / x.size


def std_ratio(gen: np.ndarray, real: np.ndarray) -> float:
    """std(generated) / std(real), over all values of the two (N, 3, H, W) sets (tactile units)."""
    return float(np.std(np.asarray(gen, np.float64)) / np.std(np.asarray(real, np.float64)))


def highpass_ratio(gen: np.ndarray, real: np.ndarray) -> float:
    """`highpass_energy` of generated over real frames."""
    return highpass_energy(gen) / highpass_energy(real)


def fit_gain(gen_train: np.ndarray, real_train: np.ndarray) -> float:
    """The contrast gain g = std(real) / std(generated) on train rows (tactile units).

    A generator whose train frames are all background (std 0) gets g = 1: there is no contrast
    to scale, and the calibration leaves its frames unchanged.
    """
    s_gen = float(np.std(np.asarray(gen_train, np.float64)))
    s_real = float(np.std(np.asarray(real_train, np.float64)))
    if not np.isfinite(s_gen) or not np.isfinite(s_real):
        raise ValueError("fit_gain: non-finite frames")
    return 1.0 if s_gen == 0.0 else s_real / s_gen


def mean_interval(
    values: np.ndarray, *, n_resamples: int, seed: int, confidence_level: float = 0.95
) -> tuple[float, float, float]:
    """(mean, low, high): the mean of per-row values with a percentile bootstrap interval over
    rows (the same resample draw as the probes' fixed-test bootstrap, `resample_indices`)."""
    from tacgen_lib.probes.bootstrap import resample_counts, resample_indices

    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 1 or v.size == 0 or not np.isfinite(v).all():
        raise ValueError(f"mean_interval: need finite per-row values, got shape {v.shape}")
    idx = resample_indices(v.size, n_resamples, seed)
    means = resample_counts(idx, v.size) @ v / v.size
    alpha = (1.0 - confidence_level) / 2.0
    lo, hi = np.quantile(means, [alpha, 1.0 - alpha])
    return float(v.mean()), float(lo), float(hi)


#: The columns of `reconstruction_row`.
RECONSTRUCTION_COLUMNS = (
    "pixel_l2",
    "pixel_l2_low",
    "pixel_l2_high",
    "ssim",
    "ssim_low",
    "ssim_high",
    "std_ratio",
    "highpass_ratio",
    "n_test",
)


def reconstruction_row(
    real_u8: np.ndarray,
    gen_u8: np.ndarray,
    real_units: np.ndarray,
    gen_units: np.ndarray,
    *,
    n_resamples: int,
    seed: int,
) -> dict[str, float]:
    """One arm's reconstruction on the test rows: mean pixel-L2 and SSIM with bootstrap
    intervals over rows (`mean_interval`), and the contrast and texture ratios of generated
    to real (`std_ratio`, `highpass_ratio`) in tactile units."""
    l2, l2_lo, l2_hi = mean_interval(pixel_l2(real_u8, gen_u8), n_resamples=n_resamples, seed=seed)
    s, s_lo, s_hi = mean_interval(ssim(real_u8, gen_u8), n_resamples=n_resamples, seed=seed)
    return {
        "pixel_l2": l2,
        "pixel_l2_low": l2_lo,
        "pixel_l2_high": l2_hi,
        "ssim": s,
        "ssim_low": s_lo,
        "ssim_high": s_hi,
        "std_ratio": std_ratio(gen_units, real_units),
        "highpass_ratio": highpass_ratio(gen_units, real_units),
        "n_test": int(len(real_u8)),
    }
