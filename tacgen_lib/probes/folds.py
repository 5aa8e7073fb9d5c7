"""Cross-validation folds on the training rows (ridge: plain K-fold; logistic: stratified),
one draw or several (repeated K-fold: a CV score is then the mean over every fold of every
draw, so the regulariser chosen hinges less on one partition of few rows)."""

from __future__ import annotations

import numpy as np

__all__ = ["make_folds"]


def make_folds(
    n: int, n_folds: int, seed: int, *, labels: np.ndarray | None = None, repeats: int = 1
) -> list[np.ndarray]:
    """Deterministic K-fold split of range(n): a list of sorted held-out index arrays.

    Rows are shuffled by ``numpy.random.default_rng(seed)``. With labels, each class is
    dealt round-robin over the folds (stratified), so every fold sees every class it can.
    With ``repeats`` = R > 1 the list holds R partitions one after another (R x K folds):
    the first is the single draw's, draw r >= 1 shuffles with ``default_rng([seed, r])``
    (a stream of its own, not another seed's first draw).
    """
    if not 2 <= n_folds <= n:
        raise ValueError(f"make_folds: need 2 <= n_folds <= n, got n_folds={n_folds}, n={n}")
    if repeats < 1:
        raise ValueError(f"make_folds: need repeats >= 1, got {repeats}")
    out = _partition(n, n_folds, np.random.default_rng(seed), labels)
    for r in range(1, repeats):
        out += _partition(n, n_folds, np.random.default_rng([seed, r]), labels)
    return out


def _partition(
    n: int, n_folds: int, rng: np.random.Generator, labels: np.ndarray | None
) -> list[np.ndarray]:
    """One K-fold partition of range(n) drawn with `rng` (stratified by `labels`)."""
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
