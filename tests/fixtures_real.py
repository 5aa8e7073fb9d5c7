"""Tiny on-disk copies of the TVL dataset (SSVTP and HCT) in its authors' layout, for tests.

The folders are built as the loaders of the TVL code release read them (github.com/Max-Fu/tvl:
``TacVisDataset`` and ``TacVisDatasetV2`` in ``tvl_enc/tacvis.py``, ``PretrainDataset`` in
``tvl_llama/data/dataset.py``; docs/real_data.md describes the layout):

- SSVTP: ``ssvtp/train.csv`` and ``test.csv`` with the header ``url,tactile,caption`` and one row
  per pair (column 0 the RGB path, read by TacVisDataset; the three columns by name, read by
  PretrainDataset), ``images_rgb/image_{i}_rgb.jpg``, ``images_tac/image_{i}_tac.jpg``,
  ``text/labels_{i}.txt``. As in a real folder, some files are not pairs the loader takes: a pair
  on disk that neither CSV lists, a listed pair with no files at all and a listed pair whose
  tactile frame is missing. The sensor background is published with the code, not the data
  (``tvl_enc/data/tac_background.png``): `write_ssvtp_fixture` writes it into a stand-in for a
  clone of the code when given one, else next to the data where docs/real_data.md says a copy
  may go.
- HCT: ``hct/data{1,2,3}/train.csv`` and ``test.csv`` with the header
  ``url,tactile,tactile_background,caption``, trajectories ``<id>-<unix time>/`` holding
  ``vision/*.jpg``, ``tactile/*.jpg`` and their background, and the path lists
  ``contact.json`` / ``not_contact.json``. One trajectory's listed background is absent and the
  loader's fallback, ``digit_background.png`` three path levels up (``hct/``), stands in for it;
  each trajectory also has a no-contact frame that only ``not_contact.json`` lists.

Tactile frames (and backgrounds) are JPEGs at the size of the published SSVTP background,
``TACTILE_SHAPE`` (its rows x columns); camera frames are small (``RGB_SHAPE``): the loaders crop
them relative to their size, so nothing depends on it. Tactile frames are a background plus a
coloured contact blob, like a DIGIT frame. Everything is seeded: the same arguments always write
the same bytes.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np

__all__ = [
    "ADJECTIVES",
    "HCT_HEADER",
    "RGB_SHAPE",
    "SSVTP_HEADER",
    "TACTILE_SHAPE",
    "write_hct_fixture",
    "write_ssvtp_fixture",
]

TACTILE_SHAPE = (320, 240)  # (rows, columns) of TVL's tvl_enc/data/tac_background.png
RGB_SHAPE = (36, 48)  # (rows, columns): a small 4:3 camera frame
ADJECTIVES = ("smooth", "rough", "hard", "soft", "glossy", "bumpy", "textured", "cool")
SSVTP_HEADER = ("url", "tactile", "caption")
HCT_HEADER = ("url", "tactile", "tactile_background", "caption")


def _background(rng: np.random.Generator) -> np.ndarray:
    """A DIGIT-like background: a smooth colour gradient with mild seeded noise (BGR uint8)."""
    h, w = TACTILE_SHAPE
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    base = rng.uniform(60, 160, size=3)
    img = base + 40 * np.stack([xx / w, yy / h, 1 - xx / w], axis=-1)
    img += rng.normal(0, 2, size=img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def _tactile(background: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Background plus a coloured Gaussian contact blob at a seeded position."""
    h, w = TACTILE_SHAPE
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    cy, cx = rng.uniform(0.3, 0.7) * h, rng.uniform(0.3, 0.7) * w
    blob = np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * (0.15 * w) ** 2))
    tint = rng.uniform(-60, 60, size=3)
    return np.clip(background + blob[..., None] * tint, 0, 255).astype(np.uint8)


def _rgb(rng: np.random.Generator) -> np.ndarray:
    """A camera frame: a random flat colour with a darker object square."""
    h, w = RGB_SHAPE
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


def _write_csv(path: Path, header: tuple[str, ...], rows: list[list[str]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)


def write_ssvtp_fixture(
    root: Path, n: int = 12, seed: int = 0, *, code: Path | None = None
) -> Path:
    """Write ``root/ssvtp`` with ``n`` pairs the loader takes; returns ``root``.

    Pair i (0 <= i < n) goes to test.csv when i % 4 == 3, else to train.csv. Beyond them:
    pair n is on disk but listed nowhere, pair n + 1 is listed in train.csv with no files, pair
    n + 2 is listed in train.csv with its tactile frame missing (the ingest skips all three and
    counts them). The background goes to ``code/tvl_enc/data/tac_background.png`` when `code`
    (a stand-in for a clone of the TVL code) is given, else to ``ssvtp/tac_background.png``.
    """
    root = Path(root)
    folder = root / "ssvtp"
    rng = np.random.default_rng(seed)
    background = _background(rng)
    if code is not None:
        _imwrite(Path(code) / "tvl_enc" / "data" / "tac_background.png", background)
    else:
        _imwrite(folder / "tac_background.png", background)
    (folder / "text").mkdir(parents=True, exist_ok=True)
    splits: dict[str, list[list[str]]] = {"train": [], "test": []}

    def pair(i: int, *, tactile: bool = True) -> list[str]:
        caption = _caption(rng, i)
        _imwrite(folder / "images_rgb" / f"image_{i}_rgb.jpg", _rgb(rng))
        if tactile:
            _imwrite(folder / "images_tac" / f"image_{i}_tac.jpg", _tactile(background, rng))
        (folder / "text" / f"labels_{i}.txt").write_text(caption + "\n", encoding="utf-8")
        return [f"images_rgb/image_{i}_rgb.jpg", f"images_tac/image_{i}_tac.jpg", caption]

    for i in range(n):
        splits["test" if i % 4 == 3 else "train"].append(pair(i))
    pair(n)  # unlisted
    splits["train"].append(  # listed, no files
        [f"images_rgb/image_{n + 1}_rgb.jpg", f"images_tac/image_{n + 1}_tac.jpg", "hard"]
    )
    splits["train"].append(pair(n + 2, tactile=False))  # listed, tactile frame missing
    for split, rows in splits.items():
        _write_csv(folder / f"{split}.csv", SSVTP_HEADER, rows)
    return root


def write_hct_fixture(root: Path, n_traj: int = 2, per_traj: int = 4, seed: int = 0) -> Path:
    """Write ``root/hct`` with ``n_traj`` trajectories of ``per_traj`` frames; returns ``root``.

    Trajectories are spread over data folders ``data1``..``data3`` (trajectory t goes to
    ``data{1 + t % 3}``, as many folders as trajectories up to three), each with its background
    ``<trajectory>/background.png`` and ``vision/``, ``tactile/`` JPEGs named like the real
    ones. Trajectory 1's background is absent: ``hct/digit_background.png`` is written for it
    (the loader's fallback). Frame k of a trajectory goes to test.csv when k % 4 == 3, else to
    train.csv; each data folder also gets ``contact.json`` listing its pairs and
    ``not_contact.json`` listing one more frame per trajectory that no CSV lists.
    """
    root = Path(root)
    hct = root / "hct"
    rng = np.random.default_rng(seed)
    n_folders = min(3, n_traj)
    rows: dict[str, dict[str, list[list[str]]]] = {
        f"data{d + 1}": {"train": [], "test": []} for d in range(n_folders)
    }
    not_contact: dict[str, list[list[str]]] = {data: [] for data in rows}
    for t in range(n_traj):
        data = f"data{1 + t % n_folders}"
        traj = f"{t}-{1702507215.615537 + 61.25 * t:.6f}"
        background = _background(rng)
        if t == 1:
            _imwrite(hct / "digit_background.png", background)
        else:
            _imwrite(hct / data / traj / "background.png", background)
        for k in range(per_traj + 1):
            frame = f"{100 + k}-{0.025303125 * (k + 1):.6f}.jpg"
            _imwrite(hct / data / traj / "vision" / frame, _rgb(rng))
            _imwrite(hct / data / traj / "tactile" / frame, _tactile(background, rng))
            row = [
                f"{traj}/vision/{frame}",
                f"{traj}/tactile/{frame}",
                f"{traj}/background.png",
            ]
            if k == per_traj:
                not_contact[data].append(row)
            else:
                rows[data]["test" if k % 4 == 3 else "train"].append([*row, _caption(rng, k)])
    for data, splits in rows.items():
        for split, split_rows in splits.items():
            _write_csv(hct / data / f"{split}.csv", HCT_HEADER, split_rows)
        every = splits["train"] + splits["test"]
        keys = ("vision", "tactile", "background")  # the keys of TVL's contact.json
        for name, listed in (("contact.json", every), ("not_contact.json", not_contact[data])):
            lists = {key: [r[i] for r in listed] for i, key in enumerate(keys)}
            (hct / data / name).write_text(json.dumps(lists, indent=1), encoding="utf-8")
    return root
