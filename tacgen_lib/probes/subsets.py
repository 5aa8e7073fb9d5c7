"""Subsets of a probe family's rows: nested training subsets and the within-scale split.

- `nested_subsets`: the training-size sweep's nested (and, for classes, stratified) subsets.
- `within_scale_split`: a random split stratified by object scale, for the held-out-scale
  diagnosis of the appearance-controlled corpus (applied to its TRAINING rows only).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["nested_subsets", "within_scale_split"]


def nested_subsets(
    n: int, sizes: Sequence[int | str], seed: int, *, labels: np.ndarray | None = None
) -> dict[int | str, np.ndarray]:
    """Sorted row indices of a nested subset of range(n) for every size ("all" = n).

    One seeded order of the rows (``default_rng(seed)``); a subset of size k is its first k
    rows, so subsets are nested. With labels, each row is keyed by its (random) rank within
    its class divided by the class size, so every prefix holds the classes in proportion
    (each class with at least one row once k >= number of classes). Sizes >= n are dropped
    ("all" covers them).
    """
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)
    if labels is not None:
        labels = np.asarray(labels, dtype=object)
        key = np.empty(n)
        for c in sorted(set(labels.tolist()), key=str):
            members = order[labels[order] == c]
            key[members] = (np.arange(members.size) + 0.5) / members.size
        order = order[np.argsort(key[order], kind="stable")]
    out: dict[int | str, np.ndarray] = {}
    for k in sizes:
        if k == "all":
            out["all"] = np.arange(n)
        elif int(k) < n:
            out[int(k)] = np.sort(order[: int(k)])
    return out


def within_scale_split(
    scale: np.ndarray, test_fraction: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """(train, test) row indices of a random split stratified by `scale`: in each scale,
    round(test_fraction x size) rows (at least 1, at most size - 1) go to test."""
    scale = np.asarray(scale)
    rng = np.random.default_rng(seed)
    test = []
    for s in sorted(set(scale.tolist())):
        members = np.flatnonzero(scale == s)
        k = min(max(1, int(round(test_fraction * members.size))), members.size - 1)
        if k >= 1:
            test.append(rng.permutation(members)[:k])
    test_idx = np.sort(np.concatenate(test)) if test else np.zeros(0, dtype=np.int64)
    train_idx = np.setdiff1d(np.arange(scale.size), test_idx)
    return train_idx, test_idx
