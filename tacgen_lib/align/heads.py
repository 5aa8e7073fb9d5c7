"""The two projection heads of InfoNCE alignment (paper eq. 1) and their use.

`ProjectionHead` (paired in `AlignHeads`) is an MLP ``Linear(in_dim, 512) -> LayerNorm(512) ->
GELU -> Linear(512, 128)`` followed by an l2-normalisation with an eps floor (`l2_normalise`), so
a zero vector maps to a finite (zero) projection instead of NaN. `project` maps features to the
aligned, l2-normalised 128-d float32 projections, from an `AlignHeads` or from the fitted heads
(`AlignResult`, what `train.fit_heads` returns). The loss is `loss`, training `train`, saving
and loading `checkpoint`, one grid cell of the stage `grid`; retrieval metrics (top-k, median
rank) live in `retrieval`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

HIDDEN_DIM = 512

OUT_DIM = 128

NORM_EPS = 1e-12


def l2_normalise(x: Tensor, eps: float = NORM_EPS) -> Tensor:
    """Rows of `x` divided by ``max(||x||_2, eps)``; a zero row stays a (finite) zero row."""
    return x / torch.linalg.vector_norm(x, dim=-1, keepdim=True).clamp_min(eps)


class ProjectionHead(nn.Module):
    """One projection head: Linear(in, 512) -> LayerNorm -> GELU -> Linear(512, 128) -> l2."""

    def __init__(self, in_dim: int, hidden_dim: int = HIDDEN_DIM, out_dim: int = OUT_DIM):
        super().__init__()
        if in_dim < 1 or hidden_dim < 1 or out_dim < 1:
            raise ValueError(
                f"ProjectionHead: dimensions must be >= 1, got in={in_dim}, "
                f"hidden={hidden_dim}, out={out_dim}"
            )
        self.in_dim, self.hidden_dim, self.out_dim = in_dim, hidden_dim, out_dim
        self.fc1 = nn.Linear(in_dim, hidden_dim)
        self.norm = nn.LayerNorm(hidden_dim)
        self.fc2 = nn.Linear(hidden_dim, out_dim)

    def forward(self, x: Tensor) -> Tensor:
        return l2_normalise(self.fc2(F.gelu(self.norm(self.fc1(x)))))


class AlignHeads(nn.Module):
    """The vision head and the tactile head, trained jointly by `fit_heads`."""

    def __init__(
        self, in_dim_v: int, in_dim_t: int, hidden_dim: int = HIDDEN_DIM, out_dim: int = OUT_DIM
    ):
        super().__init__()
        self.vision = ProjectionHead(in_dim_v, hidden_dim, out_dim)
        self.tactile = ProjectionHead(in_dim_t, hidden_dim, out_dim)

    def forward(self, v: Tensor, t: Tensor) -> tuple[Tensor, Tensor]:
        return self.vision(v), self.tactile(t)

    def dims(self) -> dict[str, int]:
        return {
            "in_dim_v": self.vision.in_dim,
            "in_dim_t": self.tactile.in_dim,
            "hidden_dim": self.vision.hidden_dim,
            "out_dim": self.vision.out_dim,
        }


def heads_from_state(dims: dict[str, int], state: dict[str, dict[str, Tensor]]) -> AlignHeads:
    heads = AlignHeads(dims["in_dim_v"], dims["in_dim_t"], dims["hidden_dim"], dims["out_dim"])
    heads.vision.load_state_dict(state["vision"])
    heads.tactile.load_state_dict(state["tactile"])
    return heads.eval()


def as_features(x: np.ndarray | Tensor, name: str) -> Tensor:
    arr = x.detach().cpu().numpy() if isinstance(x, Tensor) else np.asarray(x)
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{name}: expected a non-empty (N, d) feature matrix, got {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        raise ValueError(
            f"{name}: row {int(bad[0])} (and {bad.size - 1} more) has non-finite values; "
            "fix or drop those samples before alignment"
        )
    return torch.from_numpy(arr)


@dataclass
class AlignResult:
    """What `fit_heads` returns.

    heads: {"vision": state_dict, "tactile": state_dict} of the best-validation weights.
    dims: in_dim_v, in_dim_t, hidden_dim, out_dim. curve: one dict per evaluation with step
    (optimiser steps done), epoch (epochs done, fractional), lr, train_loss (mean training
    loss since the previous evaluation; None at step 0), val_loss, val_top1 (mean of v2t and t2v
    top-1 over the whole validation set). best_step: step of the kept weights (0 = the
    initialisation). seconds: wall time of the fit.
    """

    heads: dict[str, dict[str, Tensor]]
    dims: dict[str, int]
    config: dict[str, Any]
    curve: list[dict[str, float | None]] = field(default_factory=list)
    best_step: int = 0
    best_val_loss: float = float("nan")
    steps_run: int = 0
    total_steps: int = 0
    stopped_early: bool = False
    seconds: float = 0.0

    def module(self) -> AlignHeads:
        """The best heads as an `AlignHeads` module in eval mode."""
        return heads_from_state(self.dims, self.heads)


@torch.no_grad()
def project(
    heads: AlignHeads | AlignResult,
    v: np.ndarray | Tensor,
    t: np.ndarray | Tensor,
    *,
    chunk: int = 4096,
    device: torch.device | str,
) -> tuple[np.ndarray, np.ndarray]:
    """Aligned projections (float32, (N, 128), l2-normalised rows) of vision and touch features,
    computed on `device` (`tacgen_lib.runtime.device`; the module is moved there and back)."""
    module = heads if isinstance(heads, AlignHeads) else heads.module()
    was_training = module.training
    home = next(module.parameters()).device
    dev = torch.device(device)
    module.to(dev)
    module.eval()
    out = []
    for x, head, name in (
        (v, module.vision, "project: vision features v"),
        (t, module.tactile, "project: tactile features t"),
    ):
        xt = as_features(x, name)
        if xt.shape[1] != head.in_dim:
            raise ValueError(f"{name} have {xt.shape[1]} columns, the head expects {head.in_dim}")
        xt = xt.to(dev)
        parts = [head(xt[i : i + chunk]) for i in range(0, xt.shape[0], chunk)]
        out.append(torch.cat(parts).cpu().numpy().astype(np.float32, copy=False))
    module.train(was_training)
    module.to(home)
    return out[0], out[1]
