"""Cross-validation folds on the training rows (ridge: plain K-fold; logistic: stratified)."""

from __future__ import annotations

import numpy as np

__all__ = ["make_folds"]


def make_folds(
    n: int, n_folds: int, seed: int, *, labels: np.ndarray | None = None
) -> list[np.ndarray]:
    """Deterministic K-fold split of range(n): a list of sorted held-out index arrays.

    Rows are shuffled by ``numpy.random.default_rng(seed)``. With labels, each class is
    dealt round-robin over the folds (stratified), so every fold sees every class it can.
    """
    if not 2 <= n_folds <= n:
        raise ValueError(f"make_folds: need 2 <= n_folds <= n, got n_folds={n_folds}, n={n}")
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)
    if labels is None:
        return [np.sort(f) for f in np.array_split(order, n_folds)]
    labels = np.asarray(labels)
    assign = np.empty(n, dtype=np.int64)
    offset = 0
    for c in np.unique(labels):
        members = order[labels[order] == c]
        assign[members] = (offset + np.arange(members.size)) % n_folds
        offset += members.size
    return [np.flatnonzero(assign == k) for k in range(n_folds)]
