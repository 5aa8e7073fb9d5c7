"""Reading a real dataset's files safely: every path resolved inside the dataset root (never
out of it through an absolute path, `..` or a symlink), images decoded and checked for one
shape per role, captions parsed, and the sample and sensor tables every corpus edge holds
(errors name the file, the role and the `sample_id`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import cv2
import pandas as pd

from tacgen_lib.corpus.captions import (
    hardness_from_adjectives,
    parse_caption,
    top_pattern_strata,
)
from tacgen_lib.corpus.manifest import FRAME_COLUMNS
from tacgen_lib.io.images import decode_png, encode_png

SAMPLE_COLUMNS: tuple[str, ...] = (
    *FRAME_COLUMNS,
    "hardness",
    "stratum",
    "source_split",
    "source_path",
)


SENSOR_COLUMNS: tuple[str, ...] = ("sensor_id", "background", "corpus")


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


def load_image(path: Path, *, sample_id: str, role: str) -> Image:
    """Read an image file and re-encode it as PNG; errors name the file and the sample."""
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
    try:
        if not data:
            raise ValueError(f"{where}: file is empty")
        array = decode_png(data, where=where)
    except (ValueError, cv2.error) as err:
        raise ValueError(
            f"{where} is not a readable image ({err}); re-extract the file from the dataset"
        ) from err
    return Image(png=encode_png(array), shape=tuple(array.shape))


def check_same_shape(
    tactile: Image, background: Image, *, sample_id: str, tactile_path: Path, bg_path: Path
) -> None:
    if tactile.shape != background.shape:
        raise ValueError(
            f"sample_id '{sample_id}': tactile image {tactile_path} is {tactile.shape[:2]} but its "
            f"sensor background {bg_path} is {background.shape[:2]}; background subtraction needs "
            "equal sizes, so pass the background recorded with this sensor"
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


def corpus_frames(
    records: list[Record], sensors: dict[str, bytes], corpus: str
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Assemble the samples and sensors tables, sorted by their keys."""
    records = sorted(records, key=lambda r: r.sample_id)
    ids = [r.sample_id for r in records]
    if len(set(ids)) != len(ids):
        dup = next(i for i, c in Counter(ids).items() if c > 1)
        raise ValueError(f"{corpus}: sample_id '{dup}' occurs more than once")
    adjective_lists = [r.adjectives for r in records]
    samples = pd.DataFrame(
        {
            "sample_id": ids,
            "corpus": [corpus] * len(records),
            "rgb": pd.Series([r.rgb for r in records], dtype=object),
            "tactile": pd.Series([r.tactile for r in records], dtype=object),
            "sensor_id": [r.sensor_id for r in records],
            "caption": [r.caption for r in records],
            "adjectives": pd.Series(adjective_lists, dtype=object),
            "hardness": pd.Series(
                [hardness_from_adjectives(a) for a in adjective_lists], dtype=object
            ),
            "stratum": top_pattern_strata(adjective_lists),
            "source_split": pd.Series([r.source_split for r in records], dtype=object),
            "source_path": [r.source_path for r in records],
        },
        columns=list(SAMPLE_COLUMNS),
    )
    sensor_ids = sorted(sensors)
    sensor_table = pd.DataFrame(
        {
            "sensor_id": sensor_ids,
            "background": pd.Series([sensors[s] for s in sensor_ids], dtype=object),
            "corpus": [corpus] * len(sensor_ids),
        },
        columns=list(SENSOR_COLUMNS),
    )
    return samples, sensor_table
