"""The fused manifest: one pool of samples across corpora, keyed by `sample_id` (docs/layout.md, Corpus edges).

It holds what splits, probes and the report need (corpus, sensor, caption, labels, strata,
provenance) and no pixels. Corpora may carry different label columns (a real corpus has no
`mass`); the manifest is their union, with nulls where a corpus has no such label.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

__all__ = [
    "CORE_COLUMNS",
    "FORCE_COLUMNS",
    "FRAME_COLUMNS",
    "LABEL_COLUMNS",
    "check_labels",
    "fuse_manifest",
]

#: Columns every corpus edge carries (the corpus edge schema; see README "Corpus edges").
CORE_COLUMNS = ("sample_id", "corpus", "sensor_id", "caption", "stratum")


#: The leading columns of every corpus's samples edge, simulated or ingested: the key, the two
#: frames, the sensor and the words.
FRAME_COLUMNS = ("sample_id", "corpus", "rgb", "tactile", "sensor_id", "caption", "adjectives")

#: The contact force of the nominal press and its bands over repeated presses (N).
FORCE_COLUMNS = ("force_normal", "force_p05", "force_p50", "force_p95")

#: Numeric label columns: where a corpus carries one, every value must be finite (a NaN label
#: would silently drop or skew a probe's rows downstream).
LABEL_COLUMNS = ("scale", "density", "mass", "stiffness", "friction", *FORCE_COLUMNS)


def check_labels(frame: pd.DataFrame, *, where: str) -> None:
    """Raise ValueError naming `where` (the file), the column and the sample_id of the first
    non-finite value in a numeric label column the corpus carries."""
    for col in LABEL_COLUMNS:
        if col not in frame.columns:
            continue
        values = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=np.float64)
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"{where}: sample_id {frame['sample_id'].iloc[i]!r} has {frame[col].iloc[i]} "
                f"in label column {col!r}; labels must be finite numbers: rebuild the corpus "
                "edge or drop the sample"
            )


def fuse_manifest(
    frames: Sequence[pd.DataFrame], sources: Sequence[str] | None = None
) -> pd.DataFrame:
    """Concatenate per-corpus sample tables (pixel columns dropped) into the manifest.

    sources: the file each frame was read from, named in errors.
    Raises ValueError naming the corpus and column when a core column is missing, the file,
    column and sample_id of a non-finite label (`check_labels`), and the sample_id when two
    corpora use the same id.
    """
    parts = []
    for k, frame in enumerate(frames):
        corpus = frame["corpus"].iloc[0] if "corpus" in frame.columns and len(frame) else "?"
        for col in CORE_COLUMNS:
            if col not in frame.columns:
                raise ValueError(f"corpus {corpus!r}: samples edge has no column {col!r}")
        check_labels(frame, where=sources[k] if sources else f"corpus {corpus!r}")
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
