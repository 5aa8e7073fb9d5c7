"""The plan of an HCT ingest (TVL's ``hct/`` folder), its CSVs read as TVL's
``TacVisDatasetV2`` (``tvl_enc/tacvis.py``) and ``PretrainDataset``
(``tvl_llama/data/dataset.py``) read them; the layout and the rules are in
`tacgen_lib.corpus.ingest`'s docstring.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

from tacgen_lib.corpus.ingest_files import SPLIT_CSVS, inside_root, parsed_caption, relative_path
from tacgen_lib.corpus.ingest_plan import IngestPlan, PlannedSample, tvl_part

__all__ = ["HCT_COLUMNS", "HCT_FALLBACK_BACKGROUND", "plan_hct"]

#: HCT CSV columns, by the names of TVL's PretrainDataset, in the order TacVisDatasetV2 reads
#: them by position (vision, tactile, background, caption)
HCT_COLUMNS: tuple[str, ...] = ("url", "tactile", "tactile_background", "caption")


#: other names a header may give the same columns (the names TacVisDatasetV2 unpacks them to)
_HCT_ALIASES = {"vision": "url", "background": "tactile_background"}


HCT_FALLBACK_BACKGROUND = "digit_background.png"


def _hct_background(listed: Path) -> Path | None:
    """The row's background file, else TVL's fallback (``digit_background.png`` three path
    levels up from the listed file: TacVisDatasetV2.load_tactile_data), else None."""
    if listed.is_file():
        return listed
    if len(listed.parents) > 2:
        fallback = listed.parents[2] / HCT_FALLBACK_BACKGROUND
        if fallback.is_file():
            return fallback
    return None


def _hct_positions(csv_path: Path, header: list[str]) -> tuple[dict[str, int], str | None]:
    """Column -> position in an HCT CSV, and a note when the header is read by position."""
    names = [_HCT_ALIASES.get(c.strip().lower(), c.strip().lower()) for c in header]
    known = [c for c in HCT_COLUMNS if c in names]
    if not known:
        note = (
            f"{csv_path}: header {header} names none of {', '.join(HCT_COLUMNS)}; its columns "
            "are read by position, as TVL's TacVisDatasetV2 reads them"
        )
        return {c: i for i, c in enumerate(HCT_COLUMNS)}, note
    for column in HCT_COLUMNS:
        if column not in names:
            raise ValueError(
                f"{csv_path}: missing column '{column}' (header is {header}); HCT CSVs need the "
                f"columns {', '.join(HCT_COLUMNS)} (TVL's names) or these four by position"
            )
    return {c: names.index(c) for c in HCT_COLUMNS}, None


def _read_hct_csv(csv_path: Path, notes: list[str]) -> list[tuple[int, dict[str, str]]]:
    """(line, row) pairs of an HCT split CSV, keyed by `HCT_COLUMNS`; the first row is the
    header, as TVL's loaders take it."""
    with csv_path.open(newline="", encoding="utf-8") as handle:
        reader = csv.reader(handle)
        header = next(reader, None)
        if header is None:
            raise ValueError(
                f"{csv_path}: empty file; expected a header {','.join(HCT_COLUMNS)} and rows"
            )
        position, note = _hct_positions(csv_path, header)
        if note:
            notes.append(note)
        need = max(position.values()) + 1
        rows: list[tuple[int, dict[str, str]]] = []
        for line, row in enumerate(reader, start=2):
            if not row or not any(cell.strip() for cell in row):
                continue
            if len(row) < need:
                raise ValueError(
                    f"{csv_path}: line {line} has {len(row)} fields, need {need} "
                    f"({', '.join(HCT_COLUMNS)})"
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


def plan_hct(root: Path, *, corpus: str = "hct") -> IngestPlan:
    """Plan the ingest of TVL's HCT part (``root/hct``), reading its CSVs as TVL's loaders do
    (module docstring). Every sub-folder with a ``train.csv`` and/or ``test.csv`` is a data
    folder; each row is a sample whose ``source_split`` is its CSV's name; a vision or tactile
    file that does not exist is an error naming the CSV line and the sample_id."""
    root = Path(root)
    hct = tvl_part(root, "hct")
    backgrounds: dict[str, Path] = {}
    samples: list[PlannedSample] = []
    without: list[str] = []
    notes: list[str] = []
    for folder in _hct_data_folders(hct):
        row_number = 0
        for split, name in SPLIT_CSVS:
            csv_path = folder / name
            if not csv_path.is_file():
                continue
            for line, row in _read_hct_csv(csv_path, notes):
                sample_id = f"{corpus}-{folder.name}-{row_number:05d}"
                row_number += 1
                where = f"{csv_path}:{line}"
                adjectives = parsed_caption(row["caption"], where=where, sample_id=sample_id)
                rgb_path = Path(os.path.normpath(folder / row["url"]))
                tac_path = Path(os.path.normpath(folder / row["tactile"]))
                for role, path in (("vision", rgb_path), ("tactile", tac_path)):
                    inside_root(path, root, where=where, sample_id=sample_id, role=role)
                    if not path.is_file():
                        raise FileNotFoundError(
                            f"{where}: sample_id '{sample_id}': {role} image not found, expected "
                            f"{path}; restore the file or remove the row"
                        )
                bg_cell = row["tactile_background"]
                listed_bg = Path(os.path.normpath(folder / bg_cell)) if bg_cell else None
                bg_path = _hct_background(listed_bg) if listed_bg is not None else None
                if bg_path is None:
                    sensor_id = f"{corpus}-bg:" + (
                        relative_path(listed_bg, hct) if listed_bg is not None else "none"
                    )
                    without.append(sample_id)
                else:
                    inside_root(bg_path, root, where=where, sample_id=sample_id, role="background")
                    sensor_id = f"{corpus}-bg:{relative_path(bg_path, hct)}"
                    backgrounds.setdefault(sensor_id, bg_path)
                samples.append(
                    PlannedSample(
                        sample_id=sample_id,
                        rgb=rgb_path,
                        tactile=tac_path,
                        sensor_id=sensor_id,
                        caption=row["caption"],
                        adjectives=adjectives,
                        source_split=split,
                        source_path=relative_path(tac_path, root),
                    )
                )
    if not samples:
        raise ValueError(f"no HCT samples under {hct}: the split CSVs have no data rows")
    samples.sort(key=lambda s: s.sample_id)
    return IngestPlan(
        corpus=corpus,
        root=root,
        samples=samples,
        backgrounds=backgrounds,
        without_background=without,
        notes=notes,
    )
