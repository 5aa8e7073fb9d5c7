"""A seeded derangement: a permutation of range(n) with no fixed point, as one n-cycle drawn
by Sattolo's algorithm. Numpy only, so that a job which only needs the pairing broken (the
force-band control of `force_bands`) does not import the simulator that the null corpus
(`sim.samples.null_sources`) draws it for."""

from __future__ import annotations

import numpy as np

__all__ = ["sattolo_cycle"]


def sattolo_cycle(n: int, rng: np.random.Generator) -> np.ndarray:
    """A uniformly drawn n-cycle of range(n) (Sattolo's algorithm): perm[i] != i for every i
    when n >= 2. Draws n - 1 integers from `rng`, last position first."""
    perm = np.arange(n)
    for k in range(n - 1, 0, -1):
        j = int(rng.integers(k))
        perm[k], perm[j] = perm[j], perm[k]
    return perm
