"""A probe job's inputs as the probes stage's rules give them (rules/probes.smk): the family, its
corpus's declaration, its rows and its feature blocks, read the same way by every probe script
(probe, probe_training_size, probe_within_scale)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.corpus.keys import corpus_labels
from tacgen_lib.io import edges
from tacgen_lib.probes.rows import FamilyRows, trainable_family_rows
from tacgen_lib.probes.settings import ProbeFamily

__all__ = ["FamilyJob"]

Block = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class FamilyJob:
    """One probe family's job: `family` (config ``probes.families.<name>``), the declaration
    of its `corpus`, its `rows` (train + val rows the probes train on, test rows that score
    them; `trainable_family_rows`) and the `splits` they come from."""

    family: ProbeFamily
    corpus: Mapping[str, Any]
    rows: FamilyRows
    splits: pd.DataFrame

    @classmethod
    def read(cls, job: Any, *, within_scale: tuple[float, int] | None = None) -> FamilyJob:
        """The family of Snakemake job `job` (wildcard ``family``; params ``family``, its
        declaration, and ``corpus``; inputs ``manifest`` and ``splits``). `within_scale`:
        (test fraction, seed) of a within-scale re-split of the training rows."""
        family = ProbeFamily.from_config(job.wildcards.family, job.params.family)
        splits = edges.read(job.input.splits).frame
        rows = trainable_family_rows(
            edges.read(job.input.manifest).frame,
            splits,
            family,
            job.params.corpus,
            rule=job.rule,
            within_scale=within_scale,
        )
        return cls(family, job.params.corpus, rows, splits)

    @property
    def null_corpus(self) -> bool:
        """Whether the family's corpus is a null corpus (its touch carries no information)."""
        return corpus_labels(self.corpus)["null_corpus"]

    def vision(self, path: str) -> Block:
        """The family's V features (its ``vision`` column) of the edge at `path`."""
        return self.rows.read_block(path, self.family.vision)

    def tactile(
        self, variants: Iterable[str], paths: Iterable[str], *, only: str | None = None
    ) -> dict[str, Block]:
        """Preprocessing variant -> the T features (column ``vit``) of its edge, of every
        variant or `only` one."""
        return {
            variant: self.rows.read_block(path, "vit")
            for variant, path in zip(variants, paths, strict=True)
            if only is None or variant == only
        }
