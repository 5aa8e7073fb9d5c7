"""Feature rows by sample_id (numpy only, so the generator jobs that pick rows import no
scikit-learn)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["feature_block"]


def feature_block(
    source: Mapping[str, np.ndarray], ids: Sequence | np.ndarray, *, what: str | None = None
) -> np.ndarray:
    """Rows `ids` of a sample_id -> vector mapping, stacked as float64. With `what` (the
    caller's name), an id the mapping lacks is refused by a ValueError naming the caller and
    the sample_id (and how many such) rather than a bare KeyError."""
    if what is not None:
        missing = [i for i in ids if i not in source]
        if missing:
            raise ValueError(
                f"{what}: sample_id {missing[0]!r} has no vector ({len(missing)} such)"
            )
    return np.stack([source[i] for i in ids]).astype(np.float64)
