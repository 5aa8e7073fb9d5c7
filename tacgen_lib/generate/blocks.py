"""Feature rows by sample_id (numpy only, so the generator jobs that pick rows import no
scikit-learn)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["feature_block"]


def feature_block(source: Mapping[str, np.ndarray], ids: Sequence | np.ndarray) -> np.ndarray:
    """Rows `ids` of a sample_id -> vector mapping, stacked as float64."""
    return np.stack([source[i] for i in ids]).astype(np.float64)
