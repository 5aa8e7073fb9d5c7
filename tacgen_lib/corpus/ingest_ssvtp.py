"""The plan of an SSVTP ingest (TVL's ``ssvtp/`` folder), its pairs selected as TVL's
``TacVisDataset`` (``tvl_enc/tacvis.py``) selects them; the layout and the rules are in
`tacgen_lib.corpus.ingest`'s docstring.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

from tacgen_lib.corpus.ingest_files import SPLIT_CSVS, inside_root, parsed_caption, relative_path
from tacgen_lib.corpus.ingest_plan import SSVTP_RGB, IngestPlan, PlannedSample, tvl_part

__all__ = ["SSVTP_BACKGROUND_NAME", "SSVTP_CODE_BACKGROUND", "TVL_CODE", "plan_ssvtp"]


SSVTP_BACKGROUND_NAME = "tac_background.png"


#: where the TVL code release keeps the SSVTP background, inside a clone of it
SSVTP_CODE_BACKGROUND = Path("tvl_enc") / "data" / SSVTP_BACKGROUND_NAME


TVL_CODE = "github.com/Max-Fu/tvl"


def _ssvtp_background(folder: Path, background: Path | None, sensor_id: str) -> Path:
    """The SSVTP background file: `background` (a file, or a clone of the TVL code holding
    tvl_enc/data/tac_background.png), else the copy at ssvtp/tac_background.png."""
    if background is not None:
        candidates = [background, background / SSVTP_CODE_BACKGROUND]
    else:
        candidates = [folder / SSVTP_BACKGROUND_NAME]
    for path in candidates:
        if path.is_file():
            return path
    where = " or ".join(str(p) for p in candidates)
    raise FileNotFoundError(
        f"SSVTP tactile background not found at {where} (sensor '{sensor_id}'): TVL publishes "
        f"it with its code, not its data ({TVL_CODE}, {SSVTP_CODE_BACKGROUND.as_posix()}); set "
        "the corpus's `background` (corpora.<name>.background) to that file or to a clone of "
        f"the code, or copy it to {folder / SSVTP_BACKGROUND_NAME}"
    )


def _read_ssvtp_split(csv_path: Path) -> list[tuple[int, str]]:
    """(line, first cell) of every non-empty row of an SSVTP split CSV (the header included:
    like TVL's loader, the plan keeps the rows whose cell names an existing file)."""
    rows: list[tuple[int, str]] = []
    with csv_path.open(newline="", encoding="utf-8") as handle:
        for line, row in enumerate(csv.reader(handle), start=1):
            if row and row[0].strip():
                rows.append((line, row[0].strip()))
    return rows


def _ssvtp_pair(folder: Path, rgb_cell: str) -> tuple[int, Path, Path, Path] | None:
    """(index, RGB, tactile, caption paths) of the pair a CSV cell names, or None when the
    cell does not name an SSVTP RGB file (``.../image_{i}_rgb.jpg``)."""
    match = SSVTP_RGB.fullmatch(Path(rgb_cell).name)
    if match is None:
        return None
    index = int(match.group(1))
    rgb = Path(os.path.normpath(folder / rgb_cell))
    tactile = Path(os.path.normpath(folder / rgb_cell.replace("rgb", "tac")))
    return index, rgb, tactile, folder / "text" / f"labels_{index}.txt"


def _ssvtp_listed(folder: Path, corpus: str) -> dict[int, tuple[str, str, str]] | None:
    """Index -> (split, RGB cell, CSV:line) of the pairs the split CSVs list; None without
    any split CSV. A pair in both splits, or a row naming an existing file that is not an
    SSVTP RGB file, is an error naming the CSV and the line."""
    csvs = [(split, folder / name) for split, name in SPLIT_CSVS if (folder / name).is_file()]
    if not csvs:
        return None
    listed: dict[int, tuple[str, str, str]] = {}
    for split, csv_path in csvs:
        for line, cell in _read_ssvtp_split(csv_path):
            pair = _ssvtp_pair(folder, cell)
            if pair is None:
                if (folder / cell).is_file():
                    raise ValueError(
                        f"{csv_path}: line {line}: first column {cell!r} is not an SSVTP RGB path "
                        "like images_rgb/image_<i>_rgb.jpg; fix the row"
                    )
                continue  # a header, or a row naming no file: TVL's loader skips it too
            index = pair[0]
            where = f"{csv_path}:{line}"
            if index in listed and listed[index][0] != split:
                raise ValueError(
                    f"sample_id '{corpus}-{index:06d}' is listed in both {listed[index][2]} and "
                    f"{where}; a pair must be in one split only"
                )
            listed.setdefault(index, (split, cell, where))
    return listed


def plan_ssvtp(root: Path, *, corpus: str = "ssvtp", background: Path | None = None) -> IngestPlan:
    """Plan the ingest of TVL's SSVTP part (``root/ssvtp``), selecting pairs as TVL's loader
    does (module docstring); `background`: the SSVTP background file or a clone of the TVL
    code (default: ``root/ssvtp/tac_background.png``)."""
    root = Path(root)
    folder = tvl_part(root, "ssvtp")
    sensor_id = f"{corpus}-bg"
    bg_path = _ssvtp_background(folder, Path(background) if background else None, sensor_id)
    listed = _ssvtp_listed(folder, corpus)
    on_disk: dict[int, str] = {}
    rgb_dir = folder / "images_rgb"
    if rgb_dir.is_dir():
        for path in sorted(rgb_dir.iterdir()):
            match = SSVTP_RGB.fullmatch(path.name)
            if match is not None and path.is_file():
                on_disk.setdefault(int(match.group(1)), f"images_rgb/{path.name}")
    if listed is None:
        wanted = {i: (None, cell, str(rgb_dir / Path(cell).name)) for i, cell in on_disk.items()}
        unlisted: list[int] = []
    else:
        wanted = dict(listed)
        unlisted = sorted(set(on_disk) - set(listed))

    samples: list[PlannedSample] = []
    missing: list[str] = []
    for index in sorted(wanted):
        split, cell, where = wanted[index]
        sample_id = f"{corpus}-{index:06d}"
        pair = _ssvtp_pair(folder, cell)
        assert pair is not None
        _, rgb, tactile, text = pair
        for role, path in (("RGB", rgb), ("tactile", tactile), ("caption", text)):
            inside_root(path, root, where=where, sample_id=sample_id, role=role)
        absent = [p for p in (rgb, tactile, text) if not p.is_file()]
        if absent:
            missing.append(f"{sample_id} ({', '.join(relative_path(p, folder) for p in absent)})")
            continue
        try:
            caption = text.read_text(encoding="utf-8").strip()
        except (OSError, UnicodeDecodeError) as err:
            raise ValueError(f"sample_id '{sample_id}': cannot read caption {text}: {err}") from err
        samples.append(
            PlannedSample(
                sample_id=sample_id,
                rgb=rgb,
                tactile=tactile,
                sensor_id=sensor_id,
                caption=caption,
                adjectives=parsed_caption(caption, where=str(text), sample_id=sample_id),
                source_split=split,
                source_path=relative_path(tactile, root),
            )
        )
    if not samples:
        raise ValueError(
            f"no SSVTP samples under {folder}: expected train.csv / test.csv listing "
            "images_rgb/image_<i>_rgb.jpg, with images_tac/image_<i>_tac.jpg and "
            "text/labels_<i>.txt beside them"
        )
    skipped = {}
    if unlisted:
        skipped["pairs listed in neither train.csv nor test.csv"] = [
            f"{corpus}-{i:06d}" for i in unlisted
        ]
    if missing:
        skipped["listed pairs with missing files"] = missing
    return IngestPlan(
        corpus=corpus,
        root=root,
        samples=samples,
        backgrounds={sensor_id: bg_path},
        skipped=skipped,
    )
