"""Tiny on-disk copies of the real TVL layouts (SSVTP and HCT) for tests.

The files are real JPEGs written with ``cv2.imwrite`` plus the text/CSV files of the public
dataset, in exactly its folder structure (see ``tacgen_lib.corpus.ingest``), so tests exercise the same
parsing a user's download goes through. Images are small (24 x 32) and seeded: the same
arguments always write the same bytes. Tactile frames are a per-sensor background plus a
coloured contact blob, like a DIGIT frame; the background is saved next to them.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np

__all__ = ["ADJECTIVES", "IMAGE_SHAPE", "write_hct_fixture", "write_ssvtp_fixture"]

IMAGE_SHAPE = (24, 32)  # (H, W): DIGIT frames are 4:3 like this
ADJECTIVES = ("smooth", "rough", "hard", "soft", "glossy", "bumpy", "textured", "cool")
_HCT_HEADER = ("vision", "tactile", "background", "caption")


def _background(rng: np.random.Generator) -> np.ndarray:
    """A DIGIT-like background: a smooth colour gradient with mild seeded noise (BGR uint8)."""
    h, w = IMAGE_SHAPE
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    base = rng.uniform(60, 160, size=3)
    img = base + 40 * np.stack([xx / w, yy / h, 1 - xx / w], axis=-1)
    img += rng.normal(0, 2, size=img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def _tactile(background: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Background plus a coloured Gaussian contact blob at a seeded position."""
    h, w = IMAGE_SHAPE
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    cy, cx = rng.uniform(0.3, 0.7) * h, rng.uniform(0.3, 0.7) * w
    blob = np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * (0.15 * w) ** 2))
    tint = rng.uniform(-60, 60, size=3)
    return np.clip(background + blob[..., None] * tint, 0, 255).astype(np.uint8)


def _rgb(rng: np.random.Generator) -> np.ndarray:
    """A camera frame: a random flat colour with a darker object square."""
    h, w = IMAGE_SHAPE
    img = np.empty((h, w, 3), dtype=np.uint8)
    img[:] = rng.integers(0, 256, size=3, dtype=np.uint8)
    y, x = int(rng.integers(0, h // 2)), int(rng.integers(0, w // 2))
    img[y : y + h // 2, x : x + w // 2] //= 2
    return img


def _caption(rng: np.random.Generator, index: int) -> str:
    """1-3 adjectives; every third caption gets TVL-like noise (capitals, spaces, a period)."""
    count = int(rng.integers(1, 4))
    words = [ADJECTIVES[i] for i in rng.choice(len(ADJECTIVES), size=count, replace=False)]
    if index % 3 == 2:
        return " " + ",  ".join(w.capitalize() for w in words) + "."
    return ", ".join(words)


def _imwrite(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image):
        raise OSError(f"fixtures_real: cv2.imwrite failed for {path}")


def write_ssvtp_fixture(root: Path, n: int = 12, seed: int = 0) -> Path:
    """Write ``root/ssvtp`` with ``n`` pairs; returns ``root`` (what ``ingest_ssvtp`` takes).

    Pair i goes to test.csv when i % 4 == 3, else to train.csv; both CSVs have a header row
    ``vision`` and list ``images_rgb/image_{i}_rgb.jpg``. The background is
    ``ssvtp/tac_background.png``.
    """
    root = Path(root)
    folder = root / "ssvtp"
    rng = np.random.default_rng(seed)
    background = _background(rng)
    _imwrite(folder / "tac_background.png", background)
    (folder / "text").mkdir(parents=True, exist_ok=True)
    splits: dict[str, list[str]] = {"train": [], "test": []}
    for i in range(n):
        _imwrite(folder / "images_rgb" / f"image_{i}_rgb.jpg", _rgb(rng))
        _imwrite(folder / "images_tac" / f"image_{i}_tac.jpg", _tactile(background, rng))
        (folder / "text" / f"labels_{i}.txt").write_text(_caption(rng, i) + "\n", encoding="utf-8")
        splits["test" if i % 4 == 3 else "train"].append(f"images_rgb/image_{i}_rgb.jpg")
    for split, paths in splits.items():
        with (folder / f"{split}.csv").open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow(["vision"])
            writer.writerows([p] for p in paths)
    return root


def write_hct_fixture(root: Path, n_traj: int = 2, per_traj: int = 4, seed: int = 0) -> Path:
    """Write ``root/hct`` with ``n_traj`` trajectories of ``per_traj`` frames; returns ``root``.

    Trajectories are spread over data folders ``data1``/``data2`` (trajectory t goes to
    ``data{1 + t % 2}``), each trajectory with its own sensor background
    ``<trajectory>/background.png`` and ``vision/``, ``tactile/`` JPEGs named like the real ones.
    Frame k of a trajectory goes to test.csv when k % 4 == 3, else to train.csv; each data folder
    also gets the real ``contact.json`` listing its pairs.
    """
    root = Path(root)
    hct = root / "hct"
    rng = np.random.default_rng(seed)
    n_folders = min(2, n_traj)
    rows: dict[str, dict[str, list[list[str]]]] = {
        f"data{d + 1}": {"train": [], "test": []} for d in range(n_folders)
    }
    for t in range(n_traj):
        data = f"data{1 + t % n_folders}"
        traj = f"{t}-{1702507215.615537 + 61.25 * t:.6f}"
        background = _background(rng)
        _imwrite(hct / data / traj / "background.png", background)
        for k in range(per_traj):
            frame = f"{100 + k}-{0.025303125 * (k + 1):.6f}.jpg"
            _imwrite(hct / data / traj / "vision" / frame, _rgb(rng))
            _imwrite(hct / data / traj / "tactile" / frame, _tactile(background, rng))
            row = [
                f"{traj}/vision/{frame}",
                f"{traj}/tactile/{frame}",
                f"{traj}/background.png",
                _caption(rng, k),
            ]
            rows[data]["test" if k % 4 == 3 else "train"].append(row)
    for data, splits in rows.items():
        for split, split_rows in splits.items():
            with (hct / data / f"{split}.csv").open("w", newline="", encoding="utf-8") as handle:
                writer = csv.writer(handle)
                writer.writerow(_HCT_HEADER)
                writer.writerows(split_rows)
        every = splits["train"] + splits["test"]
        contact = {key: [r[i] for r in every] for i, key in enumerate(_HCT_HEADER[:3])}
        (hct / data / "contact.json").write_text(json.dumps(contact, indent=1), encoding="utf-8")
    return root
