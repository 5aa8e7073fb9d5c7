"""Validation of probe inputs: features, targets and regulariser grids.

A non-finite feature or target is reported with the offending ``sample_id`` (when given), so
the fix can be made upstream, where the sample came from.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["check_features", "check_lambdas", "check_target"]


def row_name(i: int, sample_ids: Sequence | np.ndarray | None) -> str:
    if sample_ids is None:
        return f"row {i}"
    return f"sample_id {str(sample_ids[i])!r}"


def check_features(
    X: np.ndarray, *, name: str = "X", sample_ids: Sequence | np.ndarray | None = None
) -> np.ndarray:
    """Return X as a finite float64 (n, p) array, or raise ValueError naming the bad sample.

    sample_ids, if given, must have one id per row; it is used only in error messages.
    """
    arr = np.asarray(X)
    if arr.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D (samples, features) array, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{name}: expected numeric features, got dtype {arr.dtype}")
    if sample_ids is not None and len(sample_ids) != arr.shape[0]:
        raise ValueError(
            f"{name}: {arr.shape[0]} rows but {len(sample_ids)} sample_ids; pass one id per row"
        )
    arr = np.asarray(arr, dtype=np.float64)
    finite = np.isfinite(arr)
    if not finite.all():
        i, j = np.argwhere(~finite)[0]
        raise ValueError(
            f"{name}: {row_name(int(i), sample_ids)} has non-finite value {arr[i, j]!r} in "
            f"feature column {int(j)}; fix or drop that sample upstream before probing"
        )
    return arr


def check_target(
    y: np.ndarray,
    n: int,
    *,
    name: str = "y",
    sample_ids: Sequence | np.ndarray | None = None,
    numeric: bool = True,
) -> np.ndarray:
    """Return y as a 1-D array of length n (float64 and finite when numeric)."""
    arr = np.asarray(y)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D target, got shape {arr.shape}")
    if arr.shape[0] != n:
        raise ValueError(f"{name}: {arr.shape[0]} targets for {n} feature rows; they must match")
    if not numeric:
        return arr
    arr = np.asarray(arr, dtype=np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name}: {row_name(i, sample_ids)} has non-finite target {arr[i]!r}; "
            "drop or relabel that sample"
        )
    return arr


def check_lambdas(lambdas: Sequence[float] | np.ndarray) -> np.ndarray:
    lam = np.atleast_1d(np.asarray(lambdas, dtype=np.float64))
    if lam.ndim != 1 or lam.size == 0:
        raise ValueError(f"lambdas: expected a non-empty 1-D grid, got shape {lam.shape}")
    if not (np.isfinite(lam).all() and (lam > 0).all()):
        raise ValueError(f"lambdas: every regulariser must be finite and > 0, got {lam.tolist()}")
    return lam
