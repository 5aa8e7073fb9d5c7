"""Reading a real dataset's files safely: every path resolved inside the dataset root (never
out of it through an absolute path, `..` or a symlink), images decoded as their files hold them
(JPEG orientation tags ignored, as PIL opens them), tactile frames checked against their
sensor's background and turned as TVL's code turns them (`pad_and_rotate`), captions parsed,
and the sample and sensor tables every corpus edge holds, with their Parquet schemas (errors
name the file, the role and the `sample_id`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pyarrow as pa

from tacgen_lib.corpus.captions import (
    hardness_from_adjectives,
    parse_caption,
    top_pattern_strata,
)
from tacgen_lib.corpus.manifest import FRAME_COLUMNS
from tacgen_lib.io.images import encode_png

SAMPLE_COLUMNS: tuple[str, ...] = (
    *FRAME_COLUMNS,
    "hardness",
    "stratum",
    "source_split",
    "source_path",
)


SENSOR_COLUMNS: tuple[str, ...] = ("sensor_id", "background", "corpus")


#: Arrow types of the ingested samples edge, fixed so that an edge written in row groups has one
#: schema whatever a group holds (a group whose hardness is all null stays a string column).
SAMPLE_SCHEMA = pa.schema(
    [
        ("sample_id", pa.large_string()),
        ("corpus", pa.large_string()),
        ("rgb", pa.binary()),
        ("tactile", pa.binary()),
        ("sensor_id", pa.large_string()),
        ("caption", pa.large_string()),
        ("adjectives", pa.list_(pa.string())),
        ("hardness", pa.string()),
        ("stratum", pa.large_string()),
        ("source_split", pa.string()),
        ("source_path", pa.large_string()),
    ]
)


SENSOR_SCHEMA = pa.schema(
    [("sensor_id", pa.large_string()), ("background", pa.binary()), ("corpus", pa.large_string())]
)


SPLIT_CSVS: tuple[tuple[str, str], ...] = (("train", "train.csv"), ("test", "test.csv"))


@dataclass(frozen=True)
class Image:
    png: bytes
    shape: tuple[int, ...]


@dataclass
class Record:
    sample_id: str
    rgb: bytes
    tactile: bytes
    sensor_id: str
    caption: str
    adjectives: list[str]
    source_split: str | None
    source_path: str


def pad_and_rotate(image: np.ndarray) -> np.ndarray:
    """A DIGIT frame as TVL's code feeds it to its models and subtracts its background
    (``tac_padding`` in ``tvl_enc/tacvis.py``, applied to the frame and to the background
    alike): zero-padded to a square, half of the difference on each side of the shorter axis
    (rounded down), then turned a quarter counter-clockwise. A frame whose sides differ by an
    odd number of pixels stays one short of square (as there); its turn here swaps its sides,
    where PIL's would keep the size and clip a pixel.
    """
    h, w = image.shape[:2]
    side = max(h, w)
    top, left = (side - h) // 2, (side - w) // 2
    pad = [(top, top), (left, left)] + [(0, 0)] * (image.ndim - 2)
    return np.ascontiguousarray(np.rot90(np.pad(image, pad), k=1))


def read_image(path: Path, *, sample_id: str, role: str) -> np.ndarray:
    """An image file as an (H, W, 3) uint8 RGB array, its pixels as stored (a JPEG orientation
    tag is ignored, as PIL's Image.open ignores it); errors name the file and the sample."""
    if not path.is_file():
        raise FileNotFoundError(
            f"sample_id '{sample_id}': {role} image not found, expected {path}; "
            "restore the file or remove the sample from the corpus"
        )
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ValueError(
            f"sample_id '{sample_id}': cannot read {role} image {path}: {err}"
        ) from err
    where = f"{role} image {path} (sample_id '{sample_id}')"
    flags = cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION
    try:
        if not data:
            raise ValueError(f"{where}: file is empty")
        bgr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), flags)
        if bgr is None:
            raise ValueError(f"{where}: bytes are not a decodable image")
    except (ValueError, cv2.error) as err:
        raise ValueError(
            f"{where} is not a readable image ({err}); re-extract the file from the dataset"
        ) from err
    return np.ascontiguousarray(bgr[:, :, ::-1])


def load_image(path: Path, *, sample_id: str, role: str) -> Image:
    """Read an image file and re-encode it as PNG; errors name the file and the sample."""
    array = read_image(path, sample_id=sample_id, role=role)
    return Image(png=encode_png(array), shape=tuple(array.shape))


def _size(shape: tuple[int, ...]) -> str:
    return f"{shape[0]} x {shape[1]} (rows x columns)"


def check_same_shape(
    tactile: tuple[int, ...],
    background: tuple[int, ...],
    *,
    sample_id: str,
    tactile_path: Path,
    bg_path: Path,
    rgb: tuple[int, ...] | None = None,
) -> None:
    """A tactile frame must have its sensor background's size (both as stored, before
    `pad_and_rotate`); else a ValueError naming both files, both sizes and the likely cause:
    the frame is the background's size turned a quarter (one of the two was saved in the
    other orientation), or the sample's camera frame has the background's size (its tactile
    and vision files are swapped, as in parts of TVL's first release)."""
    if tactile[:2] == background[:2]:
        return
    if tactile[:2] == background[1::-1]:
        likely = (
            "the frame is the background turned a quarter: the two were saved in different "
            "orientations; pass the background recorded with this sensor, in its frames' "
            "orientation"
        )
    elif rgb is not None and rgb[:2] == background[:2]:
        likely = (
            "the sample's vision frame has the background's size: its tactile and vision files "
            "look swapped, as in parts of TVL's first release; use the revised release "
            "(huggingface.co/datasets/yoorhim/TVL-revise), which fixes the swap"
        )
    else:
        likely = "pass the background recorded with this sensor"
    raise ValueError(
        f"sample_id '{sample_id}': tactile image {tactile_path} is {_size(tactile)} but its "
        f"sensor background {bg_path} is {_size(background)}; background subtraction needs "
        f"equal sizes: {likely}"
    )


def relative_path(path: Path, root: Path) -> str:
    """POSIX path of ``path`` relative to ``root`` (absolute when outside it)."""
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return path.as_posix()


def inside_root(path: Path, root: Path, *, where: str, sample_id: str, role: str) -> Path:
    """``path`` if the file it names, symlinks followed, lies inside the dataset ``root``.

    A CSV row naming an absolute path, a ``../`` path that climbs out of the root, or a
    symlink pointing out of it is refused: a dataset folder must not make the workflow read
    (and copy into an edge) files elsewhere on the machine.
    """
    real_root = root.resolve()
    real = path.resolve()
    if not real.is_relative_to(real_root):
        raise ValueError(
            f"{where}: sample_id '{sample_id}': {role} path {path} resolves to {real}, outside "
            f"the dataset root {real_root}; absolute paths, '../' paths that leave the root and "
            "symlinks out of it are refused: copy the file into the dataset folder"
        )
    return path


def parsed_caption(caption: str, *, where: str, sample_id: str) -> list[str]:
    adjectives = parse_caption(caption)
    if not adjectives:
        raise ValueError(
            f"{where}: empty caption for sample_id '{sample_id}' ({caption!r} has no adjectives); "
            "write comma-separated adjectives or remove the sample"
        )
    return adjectives


def samples_frame(records: list[Record], strata: dict[str, str], corpus: str) -> pd.DataFrame:
    """The samples table of `records` (in their order), each with its stratum from `strata`
    (sample_id -> stratum, computed over the whole corpus: `top_pattern_strata`)."""
    adjective_lists = [r.adjectives for r in records]
    return pd.DataFrame(
        {
            "sample_id": [r.sample_id for r in records],
            "corpus": [corpus] * len(records),
            "rgb": pd.Series([r.rgb for r in records], dtype=object),
            "tactile": pd.Series([r.tactile for r in records], dtype=object),
            "sensor_id": [r.sensor_id for r in records],
            "caption": [r.caption for r in records],
            "adjectives": pd.Series(adjective_lists, dtype=object),
            "hardness": pd.Series(
                [hardness_from_adjectives(a) for a in adjective_lists], dtype=object
            ),
            "stratum": [strata[r.sample_id] for r in records],
            "source_split": pd.Series([r.source_split for r in records], dtype=object),
            "source_path": [r.source_path for r in records],
        },
        columns=list(SAMPLE_COLUMNS),
    )


def sensors_frame(sensors: dict[str, bytes], corpus: str) -> pd.DataFrame:
    """The sensors table: one row per background (PNG bytes), sorted by sensor_id."""
    sensor_ids = sorted(sensors)
    return pd.DataFrame(
        {
            "sensor_id": sensor_ids,
            "background": pd.Series([sensors[s] for s in sensor_ids], dtype=object),
            "corpus": [corpus] * len(sensor_ids),
        },
        columns=list(SENSOR_COLUMNS),
    )


def corpus_frames(
    records: list[Record], sensors: dict[str, bytes], corpus: str
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Assemble the samples and sensors tables, sorted by their keys."""
    records = sorted(records, key=lambda r: r.sample_id)
    ids = [r.sample_id for r in records]
    if len(set(ids)) != len(ids):
        dup = next(i for i, c in Counter(ids).items() if c > 1)
        raise ValueError(f"{corpus}: sample_id '{dup}' occurs more than once")
    strata = dict(zip(ids, top_pattern_strata([r.adjectives for r in records]), strict=True))
    return samples_frame(records, strata, corpus), sensors_frame(sensors, corpus)
