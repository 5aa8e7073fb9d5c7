"""Real-corpus ingest: the TVL dataset's SSVTP and HCT folders as corpus edges (docs/real_data.md; the edge contract: docs/layout.md, Edges).

This module owns reading the public Touch-Vision-Language (TVL) dataset (Fu et al., 2024) from
disk and turning it into the two tables every corpus provides: one row per visuo-tactile sample
(images as PNG bytes, caption, adjectives, hardness label, stratum, source split) and one row
per tactile sensor background. The caption vocabulary the paper uses for real data (adjective
parsing, the hard/soft label, the top-5 adjective-pattern strata SSVTP splits are stratified
by) is `tacgen_lib.corpus.captions`.

Layouts (``root`` is the unzipped ``tvl_dataset`` folder holding ``ssvtp/`` and ``hct/``)::

    root/ssvtp/images_rgb/image_{i}_rgb.jpg     camera frame of pair i
    root/ssvtp/images_tac/image_{i}_tac.jpg     DIGIT frame of pair i
    root/ssvtp/text/labels_{i}.txt              caption, e.g. "smooth, hard, glossy"
    root/ssvtp/train.csv, test.csv              optional; first column = the RGB path
    root/ssvtp/tac_background.png               global sensor background (see below)

    root/hct/<data folder>/train.csv, test.csv  columns vision,tactile,background,caption;
                                                paths relative to the CSV's folder
    root/hct/<data folder>/<trajectory>/vision/*.jpg, tactile/*.jpg, background per trajectory

Assumptions, checked against the TVL code release (github.com/Max-Fu/tvl, ``tvl_enc/tacvis.py``):

- SSVTP CSVs: TVL reads only the first column of each row, an RGB path relative to ``ssvtp/``
  (``images_rgb/image_{i}_rgb.jpg``), and derives the tactile and text paths from the index.
  Their header names are not documented, so a first row whose first cell is not such a path is
  taken as a header. Pairs listed in neither CSV are still ingested, with ``source_split`` None.
- SSVTP background: TVL ships it with the code, not the data (``tvl_enc/data/tac_background.png``).
  Copy it to ``root/ssvtp/tac_background.png`` or pass ``background=``.
- HCT CSVs have a header row; TVL unpacks the four columns by position as
  ``vision, tactile, background, caption``. Here they are looked up by those names (case and
  surrounding spaces ignored), so a CSV with different names fails and names the column.
- HCT background: when a row's background file does not exist, TVL falls back to a
  ``digit_background.png`` higher up the tree; here the nearest ``digit_background.png`` from the
  background's folder up to ``root/hct`` is used, and its absence is an error.
- Captions: like TVL, adjectives are comma-separated and periods around them are dropped.

Identifiers: SSVTP ``sample_id`` is ``f"{corpus}-{i:06d}"``; HCT's is
``f"{corpus}-{data_folder}-{row:05d}"`` with ``row`` counting the data rows of ``train.csv`` then
``test.csv`` of that folder. SSVTP has one sensor, ``f"{corpus}-bg"``; HCT has one per background
file, ``f"{corpus}-bg:{path relative to root/hct}"``.

Every image is decoded (JPEG or PNG) and re-encoded as PNG with :func:`tacgen_lib.io.images.encode_png`
so all corpora carry the same lossless encoding. Errors name the file and the ``sample_id``; an
ingest either returns the whole corpus or raises.
"""

from __future__ import annotations

import csv
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from tacgen_lib.corpus.ingest_files import (
    SPLIT_CSVS,
    Image,
    Record,
    check_same_shape,
    corpus_frames,
    inside_root,
    load_image,
    parsed_caption,
    relative_path,
)

HCT_COLUMNS: tuple[str, ...] = ("vision", "tactile", "background", "caption")


SSVTP_BACKGROUND_NAME = "tac_background.png"


HCT_FALLBACK_BACKGROUND = "digit_background.png"


_IMAGE_EXT = r"\.(?:jpg|jpeg|png)"


_SSVTP_RGB = re.compile(rf"image_(\d+)_rgb{_IMAGE_EXT}", re.IGNORECASE)


_SSVTP_TAC = re.compile(rf"image_(\d+)_tac{_IMAGE_EXT}", re.IGNORECASE)


_SSVTP_TEXT = re.compile(r"labels_(\d+)\.txt", re.IGNORECASE)


def _index_files(folder: Path, pattern: re.Pattern[str]) -> dict[int, Path]:
    """Map index -> file for the files in ``folder`` whose whole name matches ``pattern``."""
    found: dict[int, Path] = {}
    if not folder.is_dir():
        return found
    for path in sorted(folder.iterdir()):
        match = pattern.fullmatch(path.name)
        if match is None:
            continue
        index = int(match.group(1))
        if index in found:
            raise ValueError(
                f"{folder}: two files for index {index}: {found[index].name} and {path.name}; "
                "keep one"
            )
        found[index] = path
    return found


def _read_ssvtp_split(csv_path: Path) -> dict[int, int]:
    """Indices listed in an SSVTP split CSV -> the CSV line listing them.

    The first column holds the RGB path (``images_rgb/image_{i}_rgb.jpg``); a first row whose
    first cell is not such a path is a header.
    """
    listed: dict[int, int] = {}
    with csv_path.open(newline="", encoding="utf-8") as handle:
        for line, row in enumerate(csv.reader(handle), start=1):
            if not row or not any(cell.strip() for cell in row):
                continue
            cell = row[0].strip()
            match = _SSVTP_RGB.fullmatch(Path(cell).name)
            if match is None:
                if line == 1:
                    continue  # header row
                raise ValueError(
                    f"{csv_path}: line {line}: first column {cell!r} is not an SSVTP RGB path "
                    "like images_rgb/image_<i>_rgb.jpg; fix the row"
                )
            listed.setdefault(int(match.group(1)), line)
    return listed


def _tvl_part(root: Path, part: str) -> Path:
    """The folder of one part of the TVL dataset (``root/ssvtp``, ``root/hct``); a missing one
    raises FileNotFoundError naming it."""
    folder = root / part
    if not folder.is_dir():
        raise FileNotFoundError(
            f"{part.upper()} folder {folder} not found; pass the unzipped TVL dataset folder "
            "that holds ssvtp/ and hct/"
        )
    return folder


def ingest_ssvtp(
    root: Path, *, corpus: str = "ssvtp", background: Path | None = None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Ingest TVL's SSVTP part (``root/ssvtp``) as (samples, sensors) tables.

    Samples are the union of the indices found in ``images_rgb/``, ``images_tac/``, ``text/`` and
    the split CSVs; each must have all three files. ``background`` is the global tactile
    background of the SSVTP sensor (default ``root/ssvtp/tac_background.png``). Columns:
    :data:`SAMPLE_COLUMNS` and :data:`SENSOR_COLUMNS`; rows sorted by ``sample_id``.
    """
    root = Path(root)
    folder = _tvl_part(root, "ssvtp")
    sensor_id = f"{corpus}-bg"
    bg_path = Path(background) if background is not None else folder / SSVTP_BACKGROUND_NAME
    if not bg_path.is_file():
        raise FileNotFoundError(
            f"SSVTP tactile background {bg_path} not found (sensor '{sensor_id}'); copy "
            f"tvl_enc/data/{SSVTP_BACKGROUND_NAME} from the TVL code release there or pass "
            "background=<path>"
        )
    bg = load_image(bg_path, sample_id=sensor_id, role="background")

    rgb_files = _index_files(folder / "images_rgb", _SSVTP_RGB)
    tac_files = _index_files(folder / "images_tac", _SSVTP_TAC)
    text_files = _index_files(folder / "text", _SSVTP_TEXT)
    split_of: dict[int, str] = {}
    listed_in: dict[int, str] = {}
    for split, name in SPLIT_CSVS:
        csv_path = folder / name
        if not csv_path.is_file():
            continue
        for index, line in _read_ssvtp_split(csv_path).items():
            if index in split_of and split_of[index] != split:
                raise ValueError(
                    f"sample_id '{corpus}-{index:06d}' is listed in both {listed_in[index]} and "
                    f"{csv_path}:{line}; a pair must be in one split only"
                )
            split_of[index] = split
            listed_in[index] = f"{csv_path}:{line}"

    indices = sorted(set(rgb_files) | set(tac_files) | set(text_files) | set(split_of))
    if not indices:
        raise ValueError(
            f"no SSVTP samples under {folder}: expected images_rgb/image_<i>_rgb.jpg, "
            "images_tac/image_<i>_tac.jpg and text/labels_<i>.txt"
        )

    records: list[Record] = []
    for index in indices:
        sample_id = f"{corpus}-{index:06d}"
        rgb_path = rgb_files.get(index, folder / "images_rgb" / f"image_{index}_rgb.jpg")
        tac_path = tac_files.get(index, folder / "images_tac" / f"image_{index}_tac.jpg")
        text_path = text_files.get(index, folder / "text" / f"labels_{index}.txt")
        for role, path in (("RGB", rgb_path), ("tactile", tac_path), ("caption", text_path)):
            inside_root(path, root, where=str(folder), sample_id=sample_id, role=role)
        rgb = load_image(rgb_path, sample_id=sample_id, role="RGB")
        tactile = load_image(tac_path, sample_id=sample_id, role="tactile")
        check_same_shape(tactile, bg, sample_id=sample_id, tactile_path=tac_path, bg_path=bg_path)
        if not text_path.is_file():
            raise FileNotFoundError(
                f"sample_id '{sample_id}': caption file not found, expected {text_path}; "
                "restore it or remove the pair"
            )
        try:
            caption = text_path.read_text(encoding="utf-8").strip()
        except (OSError, UnicodeDecodeError) as err:
            raise ValueError(
                f"sample_id '{sample_id}': cannot read caption {text_path}: {err}"
            ) from err
        adjectives = parsed_caption(caption, where=str(text_path), sample_id=sample_id)
        records.append(
            Record(
                sample_id=sample_id,
                rgb=rgb.png,
                tactile=tactile.png,
                sensor_id=sensor_id,
                caption=caption,
                adjectives=adjectives,
                source_split=split_of.get(index),
                source_path=relative_path(tac_path, root),
            )
        )
    return corpus_frames(records, {sensor_id: bg.png}, corpus)


def _hct_background(path: Path, hct: Path) -> Path | None:
    """The row's background file, else the nearest digit_background.png up to ``hct``."""
    if path.is_file():
        return path
    folder = path.parent
    while True:
        candidate = folder / HCT_FALLBACK_BACKGROUND
        if candidate.is_file():
            return candidate
        if folder == hct or folder == folder.parent or hct not in folder.parents:
            return None
        folder = folder.parent


def _read_hct_csv(csv_path: Path) -> list[tuple[int, dict[str, str]]]:
    """(line, row) pairs of an HCT split CSV, keyed by the lower-cased header names."""
    with csv_path.open(newline="", encoding="utf-8") as handle:
        reader = csv.reader(handle)
        header = next(reader, None)
        if header is None:
            raise ValueError(
                f"{csv_path}: empty file; expected a header {','.join(HCT_COLUMNS)} and rows"
            )
        names = [cell.strip().lower() for cell in header]
        for column in HCT_COLUMNS:
            if column not in names:
                raise ValueError(
                    f"{csv_path}: missing column '{column}' (header is {header}); HCT CSVs need "
                    f"the columns {', '.join(HCT_COLUMNS)}"
                )
        position = {column: names.index(column) for column in HCT_COLUMNS}
        rows: list[tuple[int, dict[str, str]]] = []
        for line, row in enumerate(reader, start=2):
            if not row or not any(cell.strip() for cell in row):
                continue
            if len(row) < len(names):
                raise ValueError(
                    f"{csv_path}: line {line} has {len(row)} fields, the header has {len(names)}"
                )
            rows.append((line, {c: row[i].strip() for c, i in position.items()}))
    return rows


def _hct_data_folders(hct: Path) -> list[Path]:
    folders: list[Path] = []
    for folder in sorted(p for p in hct.iterdir() if p.is_dir()):
        has_csv = any((folder / name).is_file() for _, name in SPLIT_CSVS)
        if has_csv:
            folders.append(folder)
        elif (folder / "contact.json").is_file():
            raise FileNotFoundError(
                f"HCT data folder {folder} has contact.json but neither train.csv nor test.csv; "
                "the captions come from those CSVs, so restore them"
            )
    if not folders:
        raise FileNotFoundError(
            f"no HCT data folders under {hct}: expected <folder>/train.csv or <folder>/test.csv"
        )
    return folders


def ingest_declared(root: Path, corpus: Mapping[str, Any]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(samples, sensors) of the real corpus `corpus` declares (``corpora.<name>`` with its
    ``name``: kind ssvtp, with an optional tactile ``background`` image, or hct) from `root`."""
    if corpus["kind"] == "ssvtp":
        background = Path(corpus["background"]) if corpus.get("background") else None
        return ingest_ssvtp(root, corpus=corpus["name"], background=background)
    return ingest_hct(root, corpus=corpus["name"])


def ingest_hct(root: Path, *, corpus: str = "hct") -> tuple[pd.DataFrame, pd.DataFrame]:
    """Ingest TVL's HCT part (``root/hct``) as (samples, sensors) tables.

    Every sub-folder of ``root/hct`` with a ``train.csv`` and/or ``test.csv`` is a data folder;
    each CSV row (vision, tactile, background, caption; paths relative to the CSV's folder) is a
    sample whose ``source_split`` is the CSV's name. Each distinct background file is a sensor.
    Columns: :data:`SAMPLE_COLUMNS` and :data:`SENSOR_COLUMNS`; rows sorted by ``sample_id``.
    """
    root = Path(root)
    hct = _tvl_part(root, "hct")
    backgrounds: dict[Path, tuple[str, Image]] = {}
    records: list[Record] = []
    for folder in _hct_data_folders(hct):
        row_number = 0
        for split, name in SPLIT_CSVS:
            csv_path = folder / name
            if not csv_path.is_file():
                continue
            for line, row in _read_hct_csv(csv_path):
                sample_id = f"{corpus}-{folder.name}-{row_number:05d}"
                row_number += 1
                where = f"{csv_path}:{line}"
                adjectives = parsed_caption(row["caption"], where=where, sample_id=sample_id)
                rgb_path = Path(os.path.normpath(folder / row["vision"]))
                tac_path = Path(os.path.normpath(folder / row["tactile"]))
                listed_bg = Path(os.path.normpath(folder / row["background"]))
                bg_path = _hct_background(listed_bg, hct)
                if bg_path is None:
                    raise FileNotFoundError(
                        f"sample_id '{sample_id}' ({where}): background {listed_bg} not found, "
                        f"nor a {HCT_FALLBACK_BACKGROUND} between its folder and {hct}; restore "
                        "the trajectory's background"
                    )
                for role, path in (
                    ("vision", rgb_path),
                    ("tactile", tac_path),
                    ("background", bg_path),
                ):
                    inside_root(path, root, where=where, sample_id=sample_id, role=role)
                if bg_path not in backgrounds:
                    sensor_id = f"{corpus}-bg:{relative_path(bg_path, hct)}"
                    backgrounds[bg_path] = (
                        sensor_id,
                        load_image(bg_path, sample_id=sample_id, role="background"),
                    )
                sensor_id, bg = backgrounds[bg_path]
                rgb = load_image(rgb_path, sample_id=sample_id, role="RGB")
                tactile = load_image(tac_path, sample_id=sample_id, role="tactile")
                check_same_shape(
                    tactile, bg, sample_id=sample_id, tactile_path=tac_path, bg_path=bg_path
                )
                records.append(
                    Record(
                        sample_id=sample_id,
                        rgb=rgb.png,
                        tactile=tactile.png,
                        sensor_id=sensor_id,
                        caption=row["caption"],
                        adjectives=adjectives,
                        source_split=split,
                        source_path=relative_path(tac_path, root),
                    )
                )
    if not records:
        raise ValueError(f"no HCT samples under {hct}: the split CSVs have no data rows")
    sensors = {sensor_id: image.png for sensor_id, image in backgrounds.values()}
    return corpus_frames(records, sensors, corpus)
