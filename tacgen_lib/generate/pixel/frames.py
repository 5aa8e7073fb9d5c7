"""Frames in the pixel generators' units, and back to the corpus's PNG frames.

The pixel generators (Pix2Pix, the pixel U-Net DDPM) map an RGB frame to a background-subtracted
tactile frame, the canonical ``clip128`` variant: ``clip(tactile - background + 128)``, so a
pixel with no contact is exactly 128. In the models' units (float32, NCHW):

- RGB condition: ``x / 127.5 - 1``, in [-1, 1];
- tactile: ``(x - 128) / 128``, so the background is exactly 0 and frames live in
  [-1, 127/128]. Nothing squashes or clips a model's output in these units: a generated value
  outside that range is what the model produced.

`to_uint8_tactile` is the inverse for writing PNG frames that the frozen tactile ViT reads like
the real ones. It must round and clip to 0..255 (a PNG holds nothing else); the share of values
it clipped is returned beside the frames and reported, so a model that leaves the frame range
shows instead of being hidden by the conversion.

Both modalities are area-resized (``cv2.INTER_AREA``) to the generators' frame size; a square
RGB frame is stretched to a non-square size (the map is learnt, so the stretch only costs
resolution along one axis).
"""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd

__all__ = [
    "TACTILE_BACKGROUND",
    "paired_frames",
    "resize_frames",
    "rgb_units",
    "tactile_units",
    "to_uint8_tactile",
]

#: The clip128 value of a pixel without contact.
TACTILE_BACKGROUND = 128


def resize_frames(images: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(N, H, W, 3) uint8 frames area-resized to size = (height, width), still uint8."""
    images = np.asarray(images)
    if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
        raise ValueError(
            f"resize_frames: expected (N, H, W, 3) uint8, got {images.shape} {images.dtype}"
        )
    h, w = (int(s) for s in size)
    if images.shape[1:3] == (h, w):
        return images.copy()
    out = np.empty((len(images), h, w, 3), dtype=np.uint8)
    for i, img in enumerate(images):
        out[i] = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    return out


def _nchw(images: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(images, dtype=np.float32).transpose(0, 3, 1, 2))


def rgb_units(images: np.ndarray) -> np.ndarray:
    """(N, H, W, 3) uint8 RGB -> (N, 3, H, W) float32 in [-1, 1]."""
    return _nchw(images) / np.float32(127.5) - np.float32(1.0)


def tactile_units(images: np.ndarray) -> np.ndarray:
    """(N, H, W, 3) uint8 clip128 tactile -> (N, 3, H, W) float32, background exactly 0."""
    return (_nchw(images) - np.float32(TACTILE_BACKGROUND)) / np.float32(TACTILE_BACKGROUND)


def to_uint8_tactile(x: np.ndarray) -> tuple[np.ndarray, float]:
    """(N, 3, H, W) tactile units -> ((N, H, W, 3) uint8 clip128 frames, share clipped).

    The share clipped is the fraction of values that fell outside 0..255 after
    ``round(x * 128 + 128)``: the only clipping anywhere on the generated frames' path.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 4 or x.shape[1] != 3:
        raise ValueError(f"to_uint8_tactile: expected (N, 3, H, W), got {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("to_uint8_tactile: generated frames hold non-finite values")
    v = np.rint(x * TACTILE_BACKGROUND + TACTILE_BACKGROUND)
    clipped = float(np.mean((v < 0) | (v > 255))) if v.size else 0.0
    return np.clip(v, 0, 255).astype(np.uint8).transpose(0, 2, 3, 1).copy(), clipped


def paired_frames(
    rgb: pd.DataFrame,
    tactile: pd.DataFrame,
    size: tuple[int, int],
    *,
    rgb_where: str,
    tactile_where: str,
) -> tuple[np.ndarray, np.ndarray]:
    """(RGB, clip128 tactile) uint8 stacks (N, H, W, 3) at `size`, row i of each the sample_id
    of row i of both frames (columns ``rgb`` and ``tactile_proc``, rows in the same sample_id
    order). An undecodable or odd-sized frame stops here naming the edge and the sample_id."""
    from tacgen_lib.preprocess.frames import decode_frames

    a, b = list(rgb["sample_id"]), list(tactile["sample_id"])
    if a != b:
        odd = next((x for x, y in zip(a, b, strict=False) if x != y), None)
        raise ValueError(
            f"{rgb_where} and {tactile_where}: rows differ (first sample_id {odd!r}, "
            f"{len(a)} vs {len(b)} rows); pass both in the same sample_id order"
        )
    rgb_u8 = resize_frames(decode_frames(rgb, "rgb", where=rgb_where), size)
    tac_u8 = resize_frames(decode_frames(tactile, "tactile_proc", where=tactile_where), size)
    return rgb_u8, tac_u8


class PairedEdges:
    """A corpus's RGB frames (edge `samples`, column ``rgb``) and clip128 tactile frames (edge
    `tactile`, column ``tactile_proc``), read once; `frames` pairs them row by row."""

    def __init__(self, samples: str, tactile: str) -> None:
        from tacgen_lib.io import edges

        self.samples_path, self.tactile_path = str(samples), str(tactile)
        self.samples = edges.read(samples, columns=["rgb"])
        self.tactile = edges.read(tactile, columns=["tactile_proc"])

    def frames(self, ids: list, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """`paired_frames` of sample_ids `ids` (in that order) at `size`."""
        return paired_frames(
            self.samples.subset(ids).frame,
            self.tactile.subset(ids).frame,
            size,
            rgb_where=self.samples_path,
            tactile_where=self.tactile_path,
        )
