"""The plan of a real-corpus ingest (`tacgen_lib.corpus.ingest`): the samples a TVL folder
holds, with their files (found), captions and labels, their sensors' background files, and
what the folder holds that is not ingested, before any image is read; and the size of a
dataset as its split CSVs list it, for the run-time estimate (`listed_rows`).
"""

from __future__ import annotations

import csv
import functools
import re
from dataclasses import dataclass, field
from pathlib import Path

from tacgen_lib.corpus.captions import top_pattern_strata
from tacgen_lib.corpus.ingest_files import SPLIT_CSVS

__all__ = ["IngestPlan", "PlannedSample", "SSVTP_RGB", "listed_rows", "tvl_part"]

_IMAGE_EXT = r"\.(?:jpg|jpeg|png)"


#: the name of an SSVTP camera frame, ``image_{i}_rgb.jpg``: it gives the pair's index
SSVTP_RGB = re.compile(rf"image_(\d+)_rgb{_IMAGE_EXT}", re.IGNORECASE)


# --------------------------------------------------------------------------- the plan


@dataclass(frozen=True)
class PlannedSample:
    """One sample to ingest: its files (checked to exist), caption and labels."""

    sample_id: str
    rgb: Path
    tactile: Path
    sensor_id: str
    caption: str
    adjectives: list[str]
    source_split: str | None
    source_path: str


@dataclass
class IngestPlan:
    """A corpus's samples, sorted by sample_id, their sensors' background files and what the
    dataset holds that is not ingested (`skipped`: reason -> items) or ingested without a
    background (`without_background`: sample_ids), with `notes` on how it was read."""

    corpus: str
    root: Path
    samples: list[PlannedSample]
    backgrounds: dict[str, Path]
    skipped: dict[str, list[str]] = field(default_factory=dict)
    without_background: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def strata(self) -> dict[str, str]:
        """sample_id -> stratum over the whole corpus (`top_pattern_strata`)."""
        ids = [s.sample_id for s in self.samples]
        return dict(zip(ids, top_pattern_strata([s.adjectives for s in self.samples]), strict=True))

    def summary(self) -> str:
        """One sentence: what the ingest writes, from where."""
        return (
            f"{self.corpus}: {len(self.samples)} samples, {len(self.backgrounds)} sensor "
            f"backgrounds from {self.root}"
        )

    def warnings(self) -> list[str]:
        """Sentences for the rule's log, as warnings: the counts of what is skipped and of the
        samples without a background, each with its first items, and how CSVs were read."""

        def first(items: list[str]) -> str:
            shown = ", ".join(items[:5])
            return shown + (f", ... ({len(items) - 5} more)" if len(items) > 5 else "")

        lines = [
            f"{self.corpus}: skipped {len(items)} {reason}: {first(items)}"
            for reason, items in self.skipped.items()
        ]
        if self.without_background:
            lines.append(
                f"{self.corpus}: {len(self.without_background)} samples have no tactile "
                f"background (background subtraction will refuse them): "
                f"{first(self.without_background)}"
            )
        return lines + [f"{self.corpus}: {note}" for note in self.notes]

    def report(self) -> list[str]:
        """`summary` then `warnings`."""
        return [self.summary(), *self.warnings()]


def tvl_part(root: Path, part: str) -> Path:
    """The folder of one part of the TVL dataset (``root/ssvtp``, ``root/hct``); a missing one
    raises FileNotFoundError naming it."""
    folder = root / part
    if not folder.is_dir():
        raise FileNotFoundError(
            f"{part.upper()} folder {folder} not found; pass the unzipped TVL dataset folder "
            "that holds ssvtp/ and hct/"
        )
    return folder


@functools.cache
def listed_rows(kind: str, root: str) -> int | None:
    """The rows a TVL dataset's split CSVs list, read without opening an image: SSVTP's rows
    naming an RGB file (``images_rgb/image_{i}_rgb.*``), HCT's data rows after each header.
    The size the run-time estimate prices an ingest (and its corpus's later jobs) by; None
    where ``root`` holds no such CSV."""
    folder = Path(root) / ("ssvtp" if kind == "ssvtp" else "hct")
    if kind == "ssvtp":
        paths = [folder / name for _, name in SPLIT_CSVS]
    else:
        paths = [d / name for d in sorted(folder.glob("*")) for _, name in SPLIT_CSVS]
    rows, found = 0, False
    for path in paths:
        if not path.is_file():
            continue
        found = True
        with path.open(newline="", encoding="utf-8", errors="replace") as handle:
            reader = csv.reader(handle)
            if kind == "ssvtp":
                rows += sum(
                    1 for row in reader if row and SSVTP_RGB.fullmatch(Path(row[0].strip()).name)
                )
            else:
                next(reader, None)
                rows += sum(1 for row in reader if any(cell.strip() for cell in row))
    return rows if found else None
