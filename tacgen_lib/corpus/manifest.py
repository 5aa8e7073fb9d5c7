"""The fused manifest: one pool of samples across corpora, keyed by `sample_id` (DESIGN §1).

It holds what splits, probes and the report need (corpus, sensor, caption, labels, strata,
provenance) and no pixels. Corpora may carry different label columns (a real corpus has no
`mass`); the manifest is their union, with nulls where a corpus has no such label.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

__all__ = ["CORE_COLUMNS", "fuse_manifest"]

#: Columns every corpus edge carries (the corpus edge schema; see README "Corpus edges").
CORE_COLUMNS = ("sample_id", "corpus", "sensor_id", "caption", "stratum")


def fuse_manifest(frames: Sequence[pd.DataFrame]) -> pd.DataFrame:
    """Concatenate per-corpus sample tables (pixel columns dropped) into the manifest.

    Raises ValueError naming the corpus and column when a core column is missing, and the
    sample_id when two corpora use the same id.
    """
    parts = []
    for frame in frames:
        corpus = frame["corpus"].iloc[0] if "corpus" in frame.columns and len(frame) else "?"
        for col in CORE_COLUMNS:
            if col not in frame.columns:
                raise ValueError(f"corpus {corpus!r}: samples edge has no column {col!r}")
        binary = [c for c in frame.columns if frame[c].map(lambda v: isinstance(v, bytes)).any()]
        parts.append(frame.drop(columns=binary))
    if not parts:
        raise ValueError("fuse_manifest: no corpora given")
    manifest = pd.concat(parts, ignore_index=True, sort=False)
    dup = manifest["sample_id"].duplicated()
    if dup.any():
        sid = manifest.loc[dup, "sample_id"].iloc[0]
        owners = sorted(manifest.loc[manifest["sample_id"] == sid, "corpus"].unique())
        raise ValueError(f"sample_id {sid!r} appears in more than one place (corpora: {owners})")
    if "scale" not in manifest.columns:
        manifest["scale"] = np.nan
    head = list(CORE_COLUMNS)
    return manifest[head + [c for c in manifest.columns if c not in head]].sort_values(
        "sample_id", ignore_index=True
    )
