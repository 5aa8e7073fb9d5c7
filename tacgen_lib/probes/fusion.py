"""Fusion of vision (V) and tactile (T) features into one probe input (paper's V+T variants).

This module owns the table of fusion variants (`FUSIONS`) and the one entry point
`fuse(name, v, t)`. Every variant is a fixed, parameter-free, row-wise function of the pair
(v_i, t_i): nothing is fitted, so no test row can leak into a fusion, and permuting the
rows of T permutes the pairing and nothing else (the tactile-permutation control relies on
this).

Variants
- ``concat``: [v, t]; raw backbone features (e.g. 384 + 768) or aligned projections.
- ``mean``: (v + t) / 2; inputs of the same dimension (the aligned projections, or raw
  features where V and T have the same size, e.g. two ViTs of one width).
- ``max``: element-wise maximum; same dimension.
- ``weighted_75_25`` / ``weighted_25_75``: 0.75 v + 0.25 t and 0.25 v + 0.75 t; same dimension.

No ``attention`` (dropped). The parameter-free form that stood here, scaled
dot-product self-attention over the two tokens {v, t} of a sample, weights each modality by
its norm and its agreement with the other; aligned projections have unit norm (and raw ViT
CLS vectors all have norm ~13.9), so its weight on V was 0.5 to six digits on every test row
and every ``attention`` row equalled its ``mean`` row. A real attention needs fitted
parameters (a gate or a temperature), fitted on the training rows inside every refit of
every control, which the fixed, row-wise contract above (and the batched control solvers
built on it) excludes. And for the linear probes here a learned gate adds nothing that is
not already probed: any gate that is the same for every row (a scalar or per-dimension
g . v + (1 - g) . t) gives a linear probe nested in the ``concat`` probe, whose coefficients
on v and t are free; only a row-dependent gate would differ, which is a non-linear probe.
Families of fusion covered: concatenation (``concat``), averaging (``mean``), element-wise
max (``max``) and fixed weighted sums (``weighted_*``); not attention or learned gates.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["DROPPED", "FUSIONS", "Fusion", "fuse", "fusion_table"]


@dataclass(frozen=True)
class Fusion:
    """One fusion variant: its name, what it computes, and which features it needs."""

    name: str
    description: str
    inputs: str  # "raw or aligned" | "equal dimension (...)"
    same_dim: bool
    fn: Callable[[np.ndarray, np.ndarray], np.ndarray]

    def dim(self, d_v: int, d_t: int) -> int:
        """Output dimension for inputs of dimension d_v and d_t."""
        return d_v + d_t if self.name == "concat" else d_v


def _concat(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.concatenate([v, t], axis=1)


def _mean(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    return 0.5 * (v + t)


def _max(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.maximum(v, t)


def _weighted(w_v: float) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    def fn(v: np.ndarray, t: np.ndarray) -> np.ndarray:
        return w_v * v + (1.0 - w_v) * t

    return fn


FUSIONS: dict[str, Fusion] = {
    f.name: f
    for f in [
        Fusion("concat", "[v, t] concatenated", "raw or aligned", False, _concat),
        Fusion(
            "mean", "(v + t) / 2", "equal dimension: aligned, or raw of equal size", True, _mean
        ),
        Fusion(
            "max",
            "element-wise max(v, t)",
            "equal dimension: aligned, or raw of equal size",
            True,
            _max,
        ),
        Fusion(
            "weighted_75_25",
            "0.75 v + 0.25 t",
            "equal dimension: aligned, or raw of equal size",
            True,
            _weighted(0.75),
        ),
        Fusion(
            "weighted_25_75",
            "0.25 v + 0.75 t",
            "equal dimension: aligned, or raw of equal size",
            True,
            _weighted(0.25),
        ),
    ]
}


#: Fusions that existed once, and why they are gone (a clear error for an old config).
DROPPED = {
    "attention": "parameter-free attention over unit-norm tokens equals 'mean' (see the "
    "tacgen_lib.probes.fusion docstring); use 'mean' or 'concat'",
}


def fusion_table() -> list[dict[str, str]]:
    """Rows (name, description, inputs) of `FUSIONS`, for the report."""
    return [
        {"name": f.name, "description": f.description, "inputs": f.inputs} for f in FUSIONS.values()
    ]


def fuse(name: str, v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Fuse row-paired V and T features with the variant `name` (see `FUSIONS`).

    v: (n, d_v), t: (n, d_t); row i of each belongs to the same sample. Returns float64.
    """
    if name in DROPPED:
        raise ValueError(f"fuse: fusion {name!r} was dropped: {DROPPED[name]}")
    if name not in FUSIONS:
        raise ValueError(f"fuse: unknown fusion {name!r}; choose one of {sorted(FUSIONS)}")
    spec = FUSIONS[name]
    v = np.asarray(v, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if v.ndim != 2 or t.ndim != 2:
        raise ValueError(f"fuse({name}): expected 2-D v and t, got {v.shape} and {t.shape}")
    if v.shape[0] != t.shape[0]:
        raise ValueError(
            f"fuse({name}): v has {v.shape[0]} rows and t has {t.shape[0]}; "
            "join them on sample_id first"
        )
    if spec.same_dim and v.shape[1] != t.shape[1]:
        raise ValueError(
            f"fuse({name}): needs aligned features of equal dimension, got v {v.shape[1]} "
            f"and t {t.shape[1]}; use the aligned projections or 'concat'"
        )
    return spec.fn(v, t)
