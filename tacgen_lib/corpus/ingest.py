"""Real-corpus ingest: the TVL dataset's SSVTP and HCT folders as corpus edges (docs/real_data.md; the edge contract: docs/layout.md, Edges).

This module owns reading the public Touch-Vision-Language (TVL) dataset (Fu et al., 2024) from
disk as its authors' loaders read it, and turning it into the two tables every corpus
provides: one row per visuo-tactile sample (images as PNG bytes, caption, adjectives, hardness
label, stratum, source split) and one row per tactile sensor background. The caption vocabulary
the paper uses for real data (adjective parsing, the hard/soft label, the top-5
adjective-pattern strata SSVTP splits are stratified by) is `tacgen_lib.corpus.captions`.

An ingest is planned first (`plan_ssvtp`, `plan_hct`: the CSVs and captions read, every file
found or reported, the strata fixed) and its images are read afterwards, in row groups
(`write_ingested` streams them into the edge; `ingest_ssvtp` / `ingest_hct` return the whole
tables, for small corpora and tests), so memory holds one row group of images at a time.

Layouts (``root`` is the unzipped ``tvl_dataset`` folder holding ``ssvtp/`` and ``hct/``), as
read by the loaders of the TVL code release (github.com/Max-Fu/tvl): ``TacVisDataset`` (SSVTP)
and ``TacVisDatasetV2`` (HCT) in ``tvl_enc/tacvis.py``, ``PretrainDataset`` in
``tvl_llama/data/dataset.py``::

    root/ssvtp/train.csv, test.csv              header url,tactile,caption; column 0 names the
                                                RGB file, relative to ssvtp/
    root/ssvtp/images_rgb/image_{i}_rgb.jpg     camera frame of pair i
    root/ssvtp/images_tac/image_{i}_tac.jpg     DIGIT frame of pair i
    root/ssvtp/text/labels_{i}.txt              caption, e.g. "smooth, hard, glossy."
    <TVL code>/tvl_enc/data/tac_background.png  the SSVTP sensor's background (with the code)

    root/hct/data{1,2,3}/train.csv, test.csv    header url,tactile,tactile_background,caption;
                                                paths relative to the CSV's folder
    root/hct/data*/<trajectory>/vision/*.jpg, tactile/*.jpg, and the trajectory's background
    root/hct/data*/contact.json, not_contact.json   path lists (no captions; not read here)

SSVTP, as ``TacVisDataset`` selects pairs: the pairs are the rows of ``train.csv`` and
``test.csv`` whose first cell names an existing RGB file (a header row names none); the tactile
file is that path with ``rgb`` read as ``tac``, the caption ``text/labels_{i}.txt``. A listed
pair with a missing RGB, tactile or caption file is skipped, and pairs in ``images_rgb/`` that
neither CSV lists are left out; both are counted in the plan's report, never fatal. With
neither CSV present every ``images_rgb/image_{i}_rgb.*`` is a pair, with no source split (the
loader lists the folder then). The background is found where the code publishes it: the
corpus's ``background`` (the file, or a clone of the TVL code), else a copy at
``root/ssvtp/tac_background.png``; its absence is an error naming where to get it.

HCT, as ``TacVisDatasetV2`` and ``PretrainDataset`` read it: the first row of each CSV is a
header; its columns are found by the authors' names (``url``, ``tactile``,
``tactile_background``, ``caption``; ``vision`` and ``background`` are read as the first and
third), and a header naming none of them is read by position, as ``TacVisDatasetV2`` does. A
row's background that does not exist falls back, as there, to ``digit_background.png`` three
path levels up from the listed file; a row with neither is ingested with no background (its
sensor is absent from the sensors table; the plan's report lists it, and background subtraction
refuses it by name).

Tactile frames and their backgrounds are checked to have one size (as stored; a mismatch names
both sizes and the likely swap) and then padded to a square and turned a quarter
counter-clockwise, as TVL's code does to both before subtracting (`ingest_files.pad_and_rotate`).
Camera frames are kept as stored. Every image is re-encoded as PNG
(:func:`tacgen_lib.io.images.encode_png`) so all corpora carry the same lossless encoding.

Identifiers: SSVTP ``sample_id`` is ``f"{corpus}-{i:06d}"``; HCT's is
``f"{corpus}-{data_folder}-{row:05d}"`` with ``row`` counting the data rows of ``train.csv`` then
``test.csv`` of that folder. SSVTP has one sensor, ``f"{corpus}-bg"``; HCT has one per background
file, ``f"{corpus}-bg:{path relative to root/hct}"``. Captions: like TVL, adjectives are
comma-separated and periods around them are dropped. Errors name the file and the
``sample_id``; an ingest either returns (or writes) the whole corpus or raises.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa

from tacgen_lib.corpus.ingest_files import (
    SAMPLE_SCHEMA,
    SENSOR_SCHEMA,
    Record,
    check_same_shape,
    pad_and_rotate,
    read_image,
    samples_frame,
    sensors_frame,
)
from tacgen_lib.corpus.ingest_hct import HCT_COLUMNS, plan_hct
from tacgen_lib.corpus.ingest_plan import IngestPlan, PlannedSample, listed_rows
from tacgen_lib.corpus.ingest_ssvtp import plan_ssvtp
from tacgen_lib.io import edges
from tacgen_lib.io.images import encode_png

__all__ = [
    "HCT_COLUMNS",
    "IngestPlan",
    "PlannedSample",
    "ROW_GROUP_BYTES",
    "ingest_declared",
    "ingest_hct",
    "ingest_ssvtp",
    "listed_rows",
    "load_ingested",
    "plan_declared",
    "plan_hct",
    "plan_ssvtp",
    "write_ingested",
]


#: PNG bytes of images a row group of the samples edge holds before it is written: what bounds
#: the ingest's memory (with the plan's text and the backgrounds' sizes)
ROW_GROUP_BYTES = 64 << 20


def plan_declared(root: Path, corpus: Mapping[str, Any]) -> IngestPlan:
    """The plan of the real corpus `corpus` declares (``corpora.<name>`` with its ``name``:
    kind ssvtp, with an optional tactile ``background`` file or TVL code clone, or hct)."""
    if corpus["kind"] == "ssvtp":
        background = Path(corpus["background"]) if corpus.get("background") else None
        return plan_ssvtp(root, corpus=corpus["name"], background=background)
    return plan_hct(root, corpus=corpus["name"])


# --------------------------------------------------------------------------- the images


def _load_backgrounds(plan: IngestPlan) -> Iterator[tuple[str, tuple[int, ...], bytes]]:
    """(sensor_id, background size as stored, PNG of the padded and turned background)."""
    for sensor_id in sorted(plan.backgrounds):
        array = read_image(plan.backgrounds[sensor_id], sample_id=sensor_id, role="background")
        yield sensor_id, tuple(array.shape), encode_png(pad_and_rotate(array))


def _record(
    sample: PlannedSample, bg_shape: tuple[int, ...] | None, bg_path: Path | None
) -> Record:
    """A sample's images read, its tactile frame checked against its background (when it has
    one) and padded and turned as TVL's code does, both re-encoded as PNG."""
    rgb = read_image(sample.rgb, sample_id=sample.sample_id, role="RGB")
    tactile = read_image(sample.tactile, sample_id=sample.sample_id, role="tactile")
    if bg_shape is not None and bg_path is not None:
        check_same_shape(
            tactile.shape,
            bg_shape,
            sample_id=sample.sample_id,
            tactile_path=sample.tactile,
            bg_path=bg_path,
            rgb=rgb.shape,
        )
    return Record(
        sample_id=sample.sample_id,
        rgb=encode_png(rgb),
        tactile=encode_png(pad_and_rotate(tactile)),
        sensor_id=sample.sensor_id,
        caption=sample.caption,
        adjectives=sample.adjectives,
        source_split=sample.source_split,
        source_path=sample.source_path,
    )


def _sample_groups(
    plan: IngestPlan,
    shapes: dict[str, tuple[int, ...]],
    group_bytes: int,
    progress: Callable[[int], None] | None,
) -> Iterator[pd.DataFrame]:
    """The samples table in row groups of about `group_bytes` of PNG each, in sample_id order."""
    strata = plan.strata()
    group: list[Record] = []
    size = 0
    for done, sample in enumerate(plan.samples, start=1):
        record = _record(
            sample, shapes.get(sample.sensor_id), plan.backgrounds.get(sample.sensor_id)
        )
        group.append(record)
        size += len(record.rgb) + len(record.tactile)
        if size >= group_bytes:
            yield samples_frame(group, strata, plan.corpus)
            group, size = [], 0
        if progress is not None:
            progress(done)
    if group:
        yield samples_frame(group, strata, plan.corpus)


def load_ingested(plan: IngestPlan) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The whole (samples, sensors) tables of a plan, in memory (small corpora and tests;
    the rule streams them with `write_ingested`)."""
    shapes: dict[str, tuple[int, ...]] = {}
    sensors: dict[str, bytes] = {}
    for sensor_id, shape, png in _load_backgrounds(plan):
        shapes[sensor_id] = shape
        sensors[sensor_id] = png
    groups = list(_sample_groups(plan, shapes, group_bytes=1 << 62, progress=None))
    return groups[0].reset_index(drop=True), sensors_frame(sensors, plan.corpus)


def write_ingested(
    plan: IngestPlan,
    samples_path: str | os.PathLike,
    sensors_path: str | os.PathLike,
    *,
    producer: str = "",
    group_bytes: int = ROW_GROUP_BYTES,
    progress: Callable[[int], None] | None = None,
) -> tuple[int, int]:
    """Write a plan's samples and sensors edges, reading its images one row group at a time
    (about `group_bytes` of PNG), so memory holds one group, never the corpus. Returns the
    (samples, sensors) row counts. `progress(samples done)` is called after each sample."""
    shapes: dict[str, tuple[int, ...]] = {}

    def sensor_groups() -> Iterator[pa.Table]:
        for sensor_id, shape, png in _load_backgrounds(plan):
            shapes[sensor_id] = shape
            yield pa.Table.from_pandas(
                sensors_frame({sensor_id: png}, plan.corpus),
                schema=SENSOR_SCHEMA,
                preserve_index=False,
            )

    n_sensors = edges.write_batches(
        sensors_path, SENSOR_SCHEMA, sensor_groups(), key="sensor_id", producer=producer
    )
    groups = (
        pa.Table.from_pandas(frame, schema=SAMPLE_SCHEMA, preserve_index=False)
        for frame in _sample_groups(plan, shapes, group_bytes, progress)
    )
    n_samples = edges.write_batches(samples_path, SAMPLE_SCHEMA, groups, producer=producer)
    return n_samples, n_sensors


def ingest_ssvtp(
    root: Path, *, corpus: str = "ssvtp", background: Path | None = None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """TVL's SSVTP part (``root/ssvtp``) as (samples, sensors) tables in memory: `plan_ssvtp`
    then `load_ingested`. Columns: :data:`SAMPLE_COLUMNS` and :data:`SENSOR_COLUMNS`; rows
    sorted by ``sample_id``."""
    return load_ingested(plan_ssvtp(root, corpus=corpus, background=background))


def ingest_hct(root: Path, *, corpus: str = "hct") -> tuple[pd.DataFrame, pd.DataFrame]:
    """TVL's HCT part (``root/hct``) as (samples, sensors) tables in memory: `plan_hct` then
    `load_ingested`. Each distinct background file is a sensor; rows sorted by ``sample_id``."""
    return load_ingested(plan_hct(root, corpus=corpus))


def ingest_declared(root: Path, corpus: Mapping[str, Any]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(samples, sensors) of the real corpus `corpus` declares, in memory (`plan_declared`)."""
    return load_ingested(plan_declared(root, corpus))
