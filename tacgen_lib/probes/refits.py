"""Many refits of one probe at its fixed regulariser: what the controls ask of a probe.

Every control (tactile and label permutations, random features, training resamples) is B
refits of the probe that the comparison chose by cross-validation, each scored on the test
rows. `Refits` describes the B problems without materialising them: column blocks of the
design (`objective.DesignBlock`: shared data, or private per problem, with a row permutation
per problem), per-problem targets, bootstrap rows, and the fusion of the two blocks. A probe's
``refit_many`` (`FixedRidge`, `FixedLogistic`) solves them together where its batched solver
applies and otherwise one at a time (`Refits.problem`), returning `Refitted` predictions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from tacgen_lib.probes.fusion import FUSIONS, fuse
from tacgen_lib.probes.objective import DesignBlock

__all__ = ["FixedProbe", "Refits", "Refitted"]


@dataclass(frozen=True)
class Refits:
    """B refits: problem b trains on the design of `train` for problem b and predicts `test`.

    train, test: one block (the design itself) or two (V and T, combined by `fusion`); a
    block's data is shared (n, d) or private (B, n, d), its ``perm`` (B, n) permutes its rows
    per problem. y: (n,) shared or (B, n) per problem. rows: (B, n) bootstrap row indices of
    the training rows per problem (the design and y are taken at those rows).
    """

    train: tuple[DesignBlock, ...]
    test: tuple[DesignBlock, ...]
    y: np.ndarray
    rows: np.ndarray | None = None
    fusion: str = "concat"

    @property
    def n_problems(self) -> int:
        """B, from whichever part varies per problem (1 when nothing does)."""
        cands = [self.y.shape[0] if np.ndim(self.y) == 2 else None]
        cands += [None if self.rows is None else self.rows.shape[0]]
        for blk in (*self.train, *self.test):
            cands += [None if blk.perm is None else blk.perm.shape[0]]
            cands += [blk.data.shape[0] if blk.data.ndim == 3 else None]
        return next((c for c in cands if c is not None), 1)

    @property
    def n_train(self) -> int:
        return int(self.train[0].data.shape[-2])

    @property
    def n_test(self) -> int:
        return int(self.test[0].data.shape[-2])

    @property
    def n_features(self) -> int:
        """Columns of one problem's design."""
        dims = [blk.dim for blk in self.train]
        return dims[0] if len(dims) == 1 else FUSIONS[self.fusion].dim(*dims)

    @property
    def shared_design(self) -> bool:
        """True when every problem has the same rows and columns, up to row permutations of
        a block (a batched solver can then precondition all problems with one scatter)."""
        return self.rows is None and all(blk.data.ndim == 2 for blk in self.train)

    def problem_design(self, blocks: tuple[DesignBlock, ...], b: int) -> np.ndarray:
        """Problem b's design from its blocks: each block's data (its own, if private) at its
        permuted rows, fused (two blocks) or as is (one)."""
        parts = []
        for blk in blocks:
            data = blk.data if blk.data.ndim == 2 else blk.data[b]
            parts.append(data if blk.perm is None else data[blk.perm[b]])
        return parts[0] if len(parts) == 1 else fuse(self.fusion, *parts)

    def problem(self, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Problem b materialised: (X_train, y_train, X_test)."""
        x_train = self.problem_design(self.train, b)
        y = self.y if np.ndim(self.y) == 1 else self.y[b]
        if self.rows is not None:
            x_train, y = x_train[self.rows[b]], y[self.rows[b]]
        return x_train, y, self.problem_design(self.test, b)

    def loop(
        self,
        fit_predict: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
        problems: np.ndarray | None = None,
    ) -> np.ndarray:
        """(len(problems), m) test predictions, one refit per problem (default: all B)."""
        todo = range(self.n_problems) if problems is None else problems
        preds = [np.asarray(fit_predict(*self.problem(int(b)))) for b in todo]
        return np.stack(preds) if preds else np.empty((0, self.n_test))


@dataclass(frozen=True)
class Refitted:
    """What ``refit_many`` returns: (B, m) test predictions, and how they were solved."""

    pred: np.ndarray
    solver: dict[str, int] = field(default_factory=dict)


class FixedProbe(Protocol):
    """A probe at a fixed regulariser (`FixedRidge`, `FixedLogistic`)."""

    def fit_predict(self, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray): ...

    def batches(self, refits: Refits) -> bool: ...

    def refit_many(self, refits: Refits, *, batched: bool | None = None) -> Refitted: ...
