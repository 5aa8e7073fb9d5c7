"""The logistic probe's objective, apart from any solver (as scikit-learn's `_linear_loss`).

This module owns what the batched solver minimises, for B problems at once:

- `DesignBlock`: one column block of B design matrices without copying them (shared data,
  a row permutation per problem, a standardisation per problem);
- `standardise_block`: the block equal to ``StandardScaler().fit_transform`` per problem;
- `LogisticObjective`: scikit-learn's lbfgs objective
  ``sum_i s_bi loss(x_bi, y_bi) / S_b + ||coef_b||^2 / (2 C S_b)`` (S_b = sum_i s_bi;
  intercept unpenalised; sigmoid loss for two classes, multinomial softmax with K coefficient
  vectors otherwise), its value and its gradient, from the margins of the current point.

The solver (`tacgen_lib.probes.batched.fit_logistic_batch`) only asks for margins, values and
gradients; it never sees the loss.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.special

__all__ = ["DesignBlock", "LogisticObjective", "standardise_block"]

_EPS = np.finfo(np.float64).eps


@dataclass(frozen=True)
class DesignBlock:
    """One column block of a batch of B design matrices (the controls' refits).

    Block of problem b = ``(rows perm[b] of data (or data[b]) - offset[b]) / scale[b]``:
    ``data`` (n, d) is shared by every problem (one GEMM serves all) or (B, n, d) private;
    ``perm`` (B, n) permutes the rows per problem (tactile-permutation control); ``offset``
    and ``scale`` ((d,) or (B, d)) standardise per problem without copying the data
    (train resamples: each resample's own StandardScaler). None means no permutation,
    offset 0, scale 1.
    """

    data: np.ndarray
    perm: np.ndarray | None = None
    offset: np.ndarray | None = None
    scale: np.ndarray | None = None

    @property
    def dim(self) -> int:
        return int(self.data.shape[-1])

    def transform(self, data: np.ndarray, perm: np.ndarray | None = None) -> DesignBlock:
        """Other rows (the test rows) under this block's offset and scale, as
        ``StandardScaler.transform`` applies a fitted scaler."""
        return DesignBlock(np.asarray(data, dtype=np.float64), perm, self.offset, self.scale)

    def _affine(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        off = np.zeros((b, self.dim)) if self.offset is None else self.offset
        sc = np.ones((b, self.dim)) if self.scale is None else self.scale
        return np.broadcast_to(off, (b, self.dim)), np.broadcast_to(sc, (b, self.dim))

    def margins(self, w: np.ndarray) -> np.ndarray:
        """(B, n, K) products of every problem's block with its coefficients w (B, d, K)."""
        b, d, k = w.shape
        off, sc = self._affine(b)
        weff = w / sc[:, :, None]
        if self.data.ndim == 2:
            n = self.data.shape[0]
            m = (self.data @ weff.transpose(1, 0, 2).reshape(d, b * k)).reshape(n, b, k)
            m = m.transpose(1, 0, 2)
        else:
            m = np.matmul(self.data, weff)
        if self.perm is not None:
            m = np.take_along_axis(m, self.perm[:, :, None], axis=1)
        return m - np.einsum("bd,bdk->bk", off, weff)[:, None, :]

    def gradient(self, r: np.ndarray) -> np.ndarray:
        """(B, d, K): the block's transpose applied to r (B, n, K) -- d(margins)^T r."""
        b, n, k = r.shape
        off, sc = self._affine(b)
        total = r.sum(axis=1)  # (B, K), before un-permuting (a permutation keeps the sum)
        if self.perm is not None:
            rr = np.empty_like(r)
            np.put_along_axis(rr, self.perm[:, :, None], r, axis=1)
            r = rr
        if self.data.ndim == 2:
            g = (self.data.T @ r.transpose(1, 0, 2).reshape(n, b * k)).reshape(-1, b, k)
            g = g.transpose(1, 0, 2)
        else:
            g = np.matmul(self.data.transpose(0, 2, 1), r)
        return (g - off[:, :, None] * total[:, None, :]) / sc[:, :, None]


def standardise_block(
    X: np.ndarray, *, weights: np.ndarray | None = None, perm: np.ndarray | None = None
) -> DesignBlock:
    """A `DesignBlock` equal to ``StandardScaler().fit_transform`` of X per problem.

    X: (n, d) shared by every problem, or (B, n, d) private to each (one scaler per problem).
    weights (B, n), with a shared X only: row multiplicities of each problem (bootstrap
    counts), giving each problem the scaler of its own resample ``X[idx]``; without weights a
    shared X has one scaler (unchanged by a row permutation). Zero-variance columns get
    scale 1, as scikit-learn.
    """
    X = np.asarray(X, dtype=np.float64)
    if weights is None:
        mean, var = X.mean(axis=-2), X.var(axis=-2)
    else:  # moments about the full-sample mean: no cancellation for large column offsets
        weights = np.asarray(weights, dtype=np.float64)
        centre = X.mean(axis=0)
        xc = X - centre
        tot = weights.sum(axis=1, keepdims=True)
        shift = (weights @ xc) / tot
        var = np.maximum((weights @ xc**2) / tot - shift**2, 0.0)
        mean = centre + shift
    scale = np.sqrt(var)
    tiny = scale < 10 * _EPS * np.maximum(np.abs(mean), 1.0)
    scale = np.where(tiny, 1.0, scale)
    return DesignBlock(X, perm=perm, offset=mean, scale=scale)


@dataclass(frozen=True)
class LogisticObjective:
    """B L2-regularised logistic losses on the design [blocks], as scikit-learn's lbfgs scales
    them (mean loss with row weights, penalty ``1 / (C S_b)``).

    Build it with `LogisticObjective.of`, which validates the labels; the coefficients w are
    (B, p, K') with K' = 1 for two classes (sigmoid), else K (softmax), margins (B, n, K').
    """

    blocks: tuple[DesignBlock, ...]
    classes: np.ndarray  # (K,) sorted labels
    weights: np.ndarray  # (B, n) row weights of the mean loss (sum to 1 per problem)
    penalty: np.ndarray  # (B,) l2 strength of the scaled objective
    labels: np.ndarray  # (B, n) sigmoid: 1.0 for the second class; softmax: bool one-hot (B, n, K)

    @classmethod
    def of(
        cls,
        blocks: Sequence[DesignBlock],
        y: np.ndarray,
        C: float,
        *,
        sample_weight: np.ndarray | None = None,
        classes: np.ndarray | None = None,
    ) -> LogisticObjective:
        """The objective of B problems: y (B, n) or (n,) labels, sample_weight (B, n) row
        multiplicities. Every problem must hold every class (refit one that does not alone)."""
        first = blocks[0]
        y = np.asarray(y)
        cands = [y.shape[0] if y.ndim == 2 else None]
        cands += [None if sample_weight is None else np.shape(sample_weight)[0]]
        cands += [blk.perm.shape[0] for blk in blocks if blk.perm is not None]
        cands += [blk.data.shape[0] for blk in blocks if blk.data.ndim == 3]
        b = next((c for c in cands if c is not None), 1)
        n = first.data.shape[-2]
        yb = np.broadcast_to(y, (b, n)) if y.ndim == 1 else y
        cls_ = np.unique(yb) if classes is None else np.asarray(classes)
        if cls_.size < 2:
            raise ValueError("fit_logistic_batch: the training rows hold a single class")
        yi = np.searchsorted(cls_, yb)
        sw = np.ones((b, n)) if sample_weight is None else np.asarray(sample_weight, np.float64)
        counts = np.stack([((yi == c) * sw).sum(axis=1) for c in range(cls_.size)], axis=1)
        short = np.flatnonzero((counts > 0).sum(axis=1) < cls_.size)
        if short.size:
            raise ValueError(
                f"fit_logistic_batch: problem {int(short[0])} holds "
                f"{int((counts[short[0]] > 0).sum())} of {cls_.size} classes; refit it alone"
            )
        if cls_.size == 2:
            labels = (yi == 1).astype(np.float64)
        else:
            labels = np.eye(cls_.size, dtype=bool)[yi]
        wn = sw / sw.sum(axis=1, keepdims=True)
        pen = 1.0 / (C * sw.sum(axis=1))
        return cls(tuple(blocks), cls_, wn, pen, labels)

    @property
    def n_problems(self) -> int:
        return int(self.weights.shape[0])

    @property
    def n_rows(self) -> int:
        return int(self.weights.shape[1])

    @property
    def k(self) -> int:
        """Coefficient vectors per problem: 1 for two classes (sigmoid), else K."""
        return 1 if self.classes.size == 2 else int(self.classes.size)

    @property
    def dims(self) -> list[int]:
        return [blk.dim for blk in self.blocks]

    @property
    def curvature(self) -> float:
        """The loss curvature at w = 0 (sigmoid 1/4, softmax 1/K), for preconditioning."""
        return 0.25 if self.k == 1 else 1.0 / self.k

    def split(self, w: np.ndarray) -> list[np.ndarray]:
        """w (B, p, K') cut into the blocks' coefficient rows."""
        return np.split(w, np.cumsum(self.dims)[:-1], axis=1)

    def margins(self, w: np.ndarray) -> np.ndarray:
        """(B, n, K') margins of the design at coefficients w (no intercept)."""
        return sum(blk.margins(x) for blk, x in zip(self.blocks, self.split(w), strict=True))

    def loss(self, m: np.ndarray) -> np.ndarray:
        """(B,) weighted mean loss at margins m."""
        if self.k == 1:
            z = m[:, :, 0]
            return np.einsum("bn,bn->b", self.weights, np.logaddexp(0.0, z) - self.labels * z)
        lse = scipy.special.logsumexp(m, axis=2)
        picked = m[self.labels].reshape(self.n_problems, self.n_rows)
        return np.einsum("bn,bn->b", self.weights, lse - picked)

    def dloss(self, m: np.ndarray) -> np.ndarray:
        """(B, n, K') derivative of the mean loss with respect to the margins."""
        if self.k == 1:
            return ((scipy.special.expit(m[:, :, 0]) - self.labels) * self.weights)[:, :, None]
        target = self.labels.astype(np.float64)
        return (scipy.special.softmax(m, axis=2) - target) * self.weights[:, :, None]

    def value(self, w: np.ndarray, m: np.ndarray) -> np.ndarray:
        """(B,) objective at coefficients w with margins m = `margins`(w) (+ intercept)."""
        return self.loss(m) + 0.5 * self.penalty * np.einsum("bpk,bpk->b", w, w)

    def gradient(self, w: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gradient wrt the coefficients (B, p, K'), wrt the intercepts (B, K'))."""
        dm = self.dloss(m)
        gw = np.concatenate(
            [blk.gradient(x) for blk, x in zip(self.blocks, [dm] * len(self.blocks), strict=True)],
            axis=1,
        )
        gw += self.penalty[:, None, None] * w
        return gw, dm.sum(axis=1)
