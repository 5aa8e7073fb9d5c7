"""InfoNCE alignment of frozen vision and touch features (paper eq. 1).

This module owns:

- the two projection heads (`ProjectionHead`, paired in `AlignHeads`): an MLP
  ``Linear(in_dim, 512) -> LayerNorm(512) -> GELU -> Linear(512, 128)`` followed by an
  l2-normalisation with an eps floor (`l2_normalise`), so a zero vector maps to a finite
  (zero) projection instead of NaN;
- the loss: `info_nce`, the symmetric InfoNCE with in-batch negatives,
  ``0.5 * (CE(z_v z_t^T / tau, arange) + CE(z_t z_v^T / tau, arange))``, computed with
  `torch.nn.functional.log_softmax` (a log-sum-exp with max shift) in float32, and
  `info_nce_reference`, an independent float64 plain-loop version used by the tests;
- training: `fit_heads` (AdamW, cosine schedule with linear warm-up `cosine_warmup_lr`,
  gradient clipping, early stopping on the held-out validation loss keeping the best weights,
  seeded shuffling, bit-for-bit reproducible on CPU for a given seed and thread count) with two
  budgets, ``"epochs"`` and ``"steps"``;
- persistence and use: `save_heads` / `load_heads` (torch.save with deterministic content,
  hashed like an edge: a `<file>.sha256.json` sidecar, verified on load), `project`
  (features -> aligned, l2-normalised 128-d float32 projections);
- one grid cell of the alignment stage: `cell_ids` (the corpus's train/val/test rows, the
  train rows cut to `n_train` by `train_subset`) and `fit_cell` (split guard, `fit_heads`,
  retrieval on the held-out test rows, the training curve as a table).

Retrieval metrics (top-k, median rank) live in `tacgen_lib.align.retrieval`.
"""

from __future__ import annotations

import io
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from tacgen_lib.align.retrieval import (
    CHANCE_COLUMNS,
    RETRIEVAL_METRICS,
    paired_retrieval,
    retrieval_ranks,
)
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.io import edges
from tacgen_lib.optim import AdamW

__all__ = [
    "HIDDEN_DIM",
    "OUT_DIM",
    "NORM_EPS",
    "ProjectionHead",
    "AlignHeads",
    "AlignResult",
    "l2_normalise",
    "info_nce",
    "info_nce_reference",
    "cosine_warmup_lr",
    "make_optimizer",
    "train_step",
    "fit_heads",
    "project",
    "heads_payload",
    "save_heads",
    "load_heads",
    "parse_n_train",
    "train_subset",
    "cell_ids",
    "CellFit",
    "fit_cell",
]

HIDDEN_DIM = 512
OUT_DIM = 128
NORM_EPS = 1e-12
_FORMAT = "tacgen-align-heads/1"


# --------------------------------------------------------------------------------------------
# Heads
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Loss
# --------------------------------------------------------------------------------------------


def _check_pairs(z_v: Tensor, z_t: Tensor, tau: float, where: str) -> None:
    if z_v.ndim != 2 or z_t.ndim != 2 or z_v.shape != z_t.shape:
        raise ValueError(
            f"{where}: expected two (B, d) tensors of the same shape (row i of each is a "
            f"positive pair), got {tuple(z_v.shape)} and {tuple(z_t.shape)}"
        )
    if z_v.shape[0] < 1:
        raise ValueError(f"{where}: empty batch; pass at least one pair")
    try:
        ok = math.isfinite(float(tau)) and float(tau) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{where}: temperature tau must be a finite number > 0, got {tau!r}")


def info_nce(z_v: Tensor, z_t: Tensor, tau: float) -> Tensor:
    """Symmetric InfoNCE over in-batch negatives (paper eq. 1).

    z_v, z_t: (B, d) projections, normally l2-normalised (the heads' outputs); row i of each is
    a positive pair and the other B-1 rows of the other modality are its negatives.
    Returns ``0.5 * (CE(z_v z_t^T / tau, arange(B)) + CE(z_t z_v^T / tau, arange(B)))``.
    The logits are formed in float32 and reduced by `F.log_softmax` over rows (v->t) and over
    columns (t->v), i.e. cross-entropy with a max-shifted log-sum-exp, so tau down to 0.01
    stays finite; a batch of one gives exactly 0.
    """
    _check_pairs(z_v, z_t, tau, "info_nce")
    logits = (z_v.float() @ z_t.float().T) / tau
    # CE(L, arange) = -mean(diag(log_softmax(L, dim=1))); CE(L^T, arange) is the same over
    # dim=0, which avoids materialising the transpose.
    v2t = F.log_softmax(logits, dim=1).diagonal()
    t2v = F.log_softmax(logits, dim=0).diagonal()
    return -0.5 * (v2t.mean() + t2v.mean())


def info_nce_reference(z_v: Tensor, z_t: Tensor, tau: float) -> Tensor:
    """Reference for `info_nce`, for tests: float64, plain loops over pairs, autograd-able.

    Every similarity is an explicit float64 dot product; each row's log-sum-exp is written out
    with its max shift. It shares no code with `info_nce` (no log_softmax, no matmul).
    """
    _check_pairs(z_v, z_t, tau, "info_nce_reference")
    zv, zt = z_v.double(), z_t.double()
    b = zv.shape[0]
    sim = [[torch.dot(zv[i], zt[j]) / tau for j in range(b)] for i in range(b)]

    def neg_log_softmax_diag(rows: list[list[Tensor]]) -> Tensor:
        total = torch.zeros((), dtype=torch.float64)
        for i, row in enumerate(rows):
            m = max(float(x.detach()) for x in row)
            s = torch.zeros((), dtype=torch.float64)
            for x in row:
                s = s + torch.exp(x - m)
            total = total + (m + torch.log(s) - row[i])
        return total / len(rows)

    v2t = neg_log_softmax_diag(sim)
    t2v = neg_log_softmax_diag([[sim[i][j] for i in range(b)] for j in range(b)])
    return 0.5 * (v2t + t2v)


# --------------------------------------------------------------------------------------------
# Training
# --------------------------------------------------------------------------------------------


def cosine_warmup_lr(step: int, total_steps: int, base_lr: float, warmup_frac: float) -> float:
    """Learning rate of optimiser step `step` (0-based) out of `total_steps`.

    Linear warm-up over ``W = max(1, round(warmup_frac * total_steps))`` steps
    (``base_lr * (step + 1) / W``), then cosine decay from base_lr towards 0:
    ``base_lr * 0.5 * (1 + cos(pi * (step - W) / (total_steps - W)))``.
    """
    if total_steps < 1:
        raise ValueError(f"cosine_warmup_lr: total_steps must be >= 1, got {total_steps}")
    warmup = min(total_steps, max(1, round(warmup_frac * total_steps)))
    if step < warmup:
        return base_lr * (step + 1) / warmup
    decay = total_steps - warmup
    progress = (step - warmup) / decay if decay > 0 else 1.0
    return base_lr * 0.5 * (1.0 + math.cos(math.pi * min(progress, 1.0)))


def make_optimizer(heads: AlignHeads, *, lr: float, weight_decay: float) -> AdamW:
    """AdamW (betas 0.9/0.999) over both heads; torch's fused single-kernel variant, through
    `tacgen_lib.optim` (no torch._dynamo import).

    Fused AdamW is about 5x cheaper per step than the foreach variant on CPU and is
    deterministic on CPU (checked by the reproducibility test).
    """
    return AdamW(
        heads.parameters(), lr=lr, betas=(0.9, 0.999), weight_decay=weight_decay, fused=True
    )


def train_step(
    heads: AlignHeads,
    opt: AdamW,
    v_batch: Tensor,
    t_batch: Tensor,
    *,
    tau: float,
    lr: float,
    clip_grad: float,
) -> float:
    """One optimiser step on one batch of pairs; returns the batch's InfoNCE loss.

    Sets the learning rate, forward through both heads, `info_nce`, backward, gradient-norm
    clipping at `clip_grad` (<= 0 disables), AdamW step. This is the step `fit_heads` runs and
    `benchmarks/bench_align.py` times.
    """
    for group in opt.param_groups:
        group["lr"] = lr
    z_v, z_t = heads(v_batch, t_batch)
    loss = info_nce(z_v, z_t, tau)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    if clip_grad > 0:
        torch.nn.utils.clip_grad_norm_(heads.parameters(), clip_grad, foreach=True)
    opt.step()
    return float(loss.detach())


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
        return _heads_from_state(self.dims, self.heads)


def _heads_from_state(dims: dict[str, int], state: dict[str, dict[str, Tensor]]) -> AlignHeads:
    heads = AlignHeads(dims["in_dim_v"], dims["in_dim_t"], dims["hidden_dim"], dims["out_dim"])
    heads.vision.load_state_dict(state["vision"])
    heads.tactile.load_state_dict(state["tactile"])
    return heads.eval()


def _as_features(x: np.ndarray | Tensor, name: str) -> Tensor:
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


def _as_index(idx: Sequence[int] | np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(idx)
    if arr.ndim != 1 or arr.size == 0 or not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"fit_heads: {name} must be a non-empty 1-D array of row positions")
    if arr.min() < 0 or arr.max() >= n:
        raise ValueError(f"fit_heads: {name} has positions outside [0, {n}) (the feature rows)")
    if np.unique(arr).size != arr.size:
        raise ValueError(f"fit_heads: {name} repeats row positions; pass each sample once")
    return arr.astype(np.int64)


def _state_copy(heads: AlignHeads) -> dict[str, dict[str, Tensor]]:
    return {
        "vision": {k: v.detach().clone() for k, v in heads.vision.state_dict().items()},
        "tactile": {k: v.detach().clone() for k, v in heads.tactile.state_dict().items()},
    }


@torch.no_grad()
def _evaluate(
    heads: AlignHeads, v: Tensor, t: Tensor, val_idx: np.ndarray, tau: float, batch_size: int
) -> tuple[float, float]:
    """Validation loss (mean InfoNCE over fixed, balanced chunks of <= batch_size) and top-1."""
    heads.eval()
    chunks = np.array_split(val_idx, math.ceil(val_idx.size / batch_size))
    zs_v, zs_t, loss_sum = [], [], 0.0
    for chunk in chunks:
        ix = torch.from_numpy(chunk)
        z_v, z_t = heads(v[ix], t[ix])
        loss_sum += float(info_nce(z_v, z_t, tau)) * chunk.size
        zs_v.append(z_v)
        zs_t.append(z_t)
    heads.train()
    metrics = paired_retrieval(torch.cat(zs_v).numpy(), torch.cat(zs_t).numpy())
    top1 = 0.5 * (metrics["top1_v2t"] + metrics["top1_t2v"])
    return loss_sum / val_idx.size, top1


def fit_heads(
    v: np.ndarray | Tensor,
    t: np.ndarray | Tensor,
    train_idx: Sequence[int] | np.ndarray,
    val_idx: Sequence[int] | np.ndarray,
    *,
    tau: float,
    seed: int,
    settings: AlignSettings,
    progress: Callable[[str], Any] | None = None,
) -> AlignResult:
    """Train the two projection heads with symmetric InfoNCE (paper eq. 1).

    v: (N, dv) vision features, t: (N, dt) tactile features; row i of each is one sample.
    train_idx / val_idx: disjoint row positions of the alignment train and held-out validation
    samples (the caller takes them from the split edge; test rows must not be here).

    settings: the training budget and optimiser (`AlignSettings`, from config ``align``).
    Budget: ``"epochs"`` runs ``epochs * (n_train // B)`` steps, ``"steps"`` runs `steps`
    steps, with ``B = min(batch_size, n_train)``. Each epoch is a fresh seeded permutation of
    train_idx cut into full batches of B (the remainder of a permutation is dropped, so every
    step sees B - 1 negatives per query). AdamW (betas 0.9/0.999, weight_decay), learning rate
    `cosine_warmup_lr`, gradient-norm clipping at `clip_grad`.

    Evaluation at step 0 and every `eval_every` steps (and at the last step): validation loss
    and top-1; the weights with the lowest validation loss are kept. Early stopping after
    `patience` consecutive evaluations without improvement (`patience=0` disables it).
    Each step is `train_step` with the optimiser from `make_optimizer`.
    Initialisation (torch.manual_seed(seed) in a forked RNG, so global RNG state is untouched)
    and shuffling (numpy Generator(seed)) are seeded: on CPU, the same inputs, seed and
    thread count give bit-identical weights.
    """
    started = time.perf_counter()
    s = settings
    budget, epochs, steps, batch_size = s.budget, s.epochs, s.steps, s.batch_size
    lr, weight_decay, warmup_frac, clip_grad = s.lr, s.weight_decay, s.warmup_frac, s.clip_grad
    patience, eval_every = s.patience, s.eval_every
    v_t = _as_features(v, "fit_heads: vision features v")
    t_t = _as_features(t, "fit_heads: tactile features t")
    if v_t.shape[0] != t_t.shape[0]:
        raise ValueError(
            f"fit_heads: v has {v_t.shape[0]} rows but t has {t_t.shape[0]}; rows must be the "
            "same samples in the same order (join on sample_id first)"
        )
    n = v_t.shape[0]
    tr = _as_index(train_idx, n, "train_idx")
    va = _as_index(val_idx, n, "val_idx")
    overlap = np.intersect1d(tr, va)
    if overlap.size:
        raise ValueError(
            f"fit_heads: {overlap.size} rows are in both train_idx and val_idx "
            f"(first: position {int(overlap[0])}); validation rows must be held out"
        )
    if tr.size < 2:
        raise ValueError("fit_heads: InfoNCE needs >= 2 training pairs (in-batch negatives)")
    if budget not in ("epochs", "steps"):
        raise ValueError(f"fit_heads: budget must be 'epochs' or 'steps', got {budget!r}")
    for name, val, low in (("batch_size", batch_size, 2), ("eval_every", eval_every, 1)):
        if int(val) != val or val < low:
            raise ValueError(f"fit_heads: {name} must be an integer >= {low}, got {val!r}")
    if patience < 0:
        raise ValueError(f"fit_heads: patience must be >= 0 (0 disables), got {patience}")
    if not (math.isfinite(tau) and tau > 0):
        raise ValueError(f"fit_heads: tau must be > 0, got {tau!r}")

    bsz = min(int(batch_size), tr.size)
    steps_per_epoch = tr.size // bsz
    if budget == "epochs":
        if epochs < 1:
            raise ValueError(f"fit_heads: budget 'epochs' needs epochs >= 1, got {epochs}")
        total = int(epochs) * steps_per_epoch
    else:
        if steps < 1:
            raise ValueError(f"fit_heads: budget 'steps' needs steps >= 1, got {steps}")
        total = int(steps)

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        heads = AlignHeads(v_t.shape[1], t_t.shape[1])
    heads.train()
    opt = make_optimizer(heads, lr=lr, weight_decay=weight_decay)
    rng = np.random.default_rng(seed)
    config = {
        "tau": float(tau),
        "seed": int(seed),
        "budget": budget,
        "epochs": int(epochs),
        "steps": int(steps),
        "batch_size": bsz,
        "lr": float(lr),
        "weight_decay": float(weight_decay),
        "warmup_frac": float(warmup_frac),
        "clip_grad": float(clip_grad),
        "patience": int(patience),
        "eval_every": int(eval_every),
        "n_train": int(tr.size),
        "n_val": int(va.size),
    }

    curve: list[dict[str, float | None]] = []
    best_state = _state_copy(heads)
    best_loss, best_step, bad_evals = math.inf, 0, 0
    running, running_n = 0.0, 0
    stopped_early = False

    def record(step: int, lr_now: float) -> bool:
        """Evaluate; returns True when early stopping should fire."""
        nonlocal best_state, best_loss, best_step, bad_evals, running, running_n
        val_loss, val_top1 = _evaluate(heads, v_t, t_t, va, tau, bsz)
        train_loss = running / running_n if running_n else None
        running, running_n = 0.0, 0
        curve.append(
            {
                "step": step,
                "epoch": step / steps_per_epoch,
                "lr": lr_now,
                "train_loss": train_loss,
                "val_loss": val_loss,
                "val_top1": val_top1,
            }
        )
        if val_loss < best_loss:
            best_loss, best_step, bad_evals = val_loss, step, 0
            best_state = _state_copy(heads)
        else:
            bad_evals += 1
        if progress is not None:
            progress(
                f"align step {step}/{total} epoch {step / steps_per_epoch:.2f} "
                f"lr {lr_now:.3g} train_loss {'-' if train_loss is None else f'{train_loss:.4f}'} "
                f"val_loss {val_loss:.4f} "
                f"val_top1 {val_top1:.4f} best_step {best_step}"
            )
        return patience > 0 and bad_evals >= patience

    record(0, 0.0)
    order = np.empty(0, dtype=np.int64)
    step = 0
    while step < total:
        pos = step % steps_per_epoch
        if pos == 0:
            order = tr[rng.permutation(tr.size)]
        ix = torch.from_numpy(order[pos * bsz : (pos + 1) * bsz])
        lr_now = cosine_warmup_lr(step, total, lr, warmup_frac)
        loss = train_step(heads, opt, v_t[ix], t_t[ix], tau=tau, lr=lr_now, clip_grad=clip_grad)
        if not math.isfinite(loss):
            raise FloatingPointError(
                f"fit_heads: training loss became {loss} at step {step} "
                f"(tau={tau}, lr={lr_now:.3g}); lower lr or raise tau"
            )
        running += loss
        running_n += 1
        step += 1
        if step % eval_every == 0 or step == total:
            if record(step, lr_now) and step < total:
                stopped_early = True
                break

    return AlignResult(
        heads=best_state,
        dims=heads.dims(),
        config=config,
        curve=curve,
        best_step=best_step,
        best_val_loss=best_loss,
        steps_run=step,
        total_steps=total,
        stopped_early=stopped_early,
        seconds=time.perf_counter() - started,
    )


# --------------------------------------------------------------------------------------------
# Use and persistence
# --------------------------------------------------------------------------------------------


@torch.no_grad()
def project(
    heads: AlignHeads | AlignResult,
    v: np.ndarray | Tensor,
    t: np.ndarray | Tensor,
    *,
    chunk: int = 4096,
) -> tuple[np.ndarray, np.ndarray]:
    """Aligned projections (float32, (N, 128), l2-normalised rows) of vision and touch features."""
    module = heads.module() if isinstance(heads, AlignResult) else heads
    was_training = module.training
    module.eval()
    out = []
    for x, head, name in (
        (v, module.vision, "project: vision features v"),
        (t, module.tactile, "project: tactile features t"),
    ):
        xt = _as_features(x, name)
        if xt.shape[1] != head.in_dim:
            raise ValueError(f"{name} have {xt.shape[1]} columns, the head expects {head.in_dim}")
        parts = [head(xt[i : i + chunk]) for i in range(0, xt.shape[0], chunk)]
        out.append(torch.cat(parts).numpy().astype(np.float32, copy=False))
    module.train(was_training)
    return out[0], out[1]


def heads_payload(result: AlignResult) -> dict[str, Any]:
    """What `save_heads` serialises: format, dims, config, curve and both heads' weights."""
    return {
        "format": _FORMAT,
        "dims": dict(result.dims),
        "config": dict(result.config),
        "best_step": int(result.best_step),
        "best_val_loss": float(result.best_val_loss),
        "steps_run": int(result.steps_run),
        "total_steps": int(result.total_steps),
        "stopped_early": bool(result.stopped_early),
        "curve": [dict(c) for c in result.curve],
        "vision": result.heads["vision"],
        "tactile": result.heads["tactile"],
    }


def save_heads(result: AlignResult, path: str | os.PathLike[str], *, producer: str = "") -> str:
    """Write the best heads, dims, config and curve with torch.save, atomically; returns SHA-256.

    The content is deterministic: wall-clock seconds are not stored and the bytes are
    serialised in memory (so the zip's internal folder name does not depend on a temp file
    name) before a temp-file + rename. Same fit => same file bytes.
    Like an edge, the file gets a `<file>.sha256.json` sidecar (written first, see
    `tacgen_lib.io.edges`) naming its hash, the two heads' shapes and the producing rule, so the
    report's edge manifest lists it and `load_heads` refuses a file changed after it was written.
    """
    buf = io.BytesIO()
    torch.save(heads_payload(result), buf)
    data = buf.getvalue()
    dims = result.dims
    layers = f"{dims['hidden_dim']}->{dims['out_dim']}"
    return edges.write_bytes(
        path,
        data,
        rows=2,
        key="head",
        columns={
            "vision": f"mlp {dims['in_dim_v']}->{layers}",
            "tactile": f"mlp {dims['in_dim_t']}->{layers}",
        },
        vectors={},
        producer=producer,
    )


def load_heads(path: str | os.PathLike[str], *, verify: bool = True) -> AlignHeads:
    """Load heads written by `save_heads` as an `AlignHeads` module in eval mode.

    verify: check the file's SHA-256 against its sidecar first (`edges.verify`).
    The stored metadata (config, curve, best_step...) is attached as ``heads.meta``.
    """
    if verify:
        edges.verify(path)
    try:
        payload = torch.load(os.fspath(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - re-raised with the file named
        raise ValueError(f"{path}: not a readable heads file ({exc}); rerun train_heads") from exc
    if not isinstance(payload, dict) or payload.get("format") != _FORMAT:
        raise ValueError(f"{path}: not a {_FORMAT} file; rerun train_heads to regenerate it")
    heads = _heads_from_state(payload["dims"], payload)
    heads.meta = {k: v for k, v in payload.items() if k not in ("vision", "tactile")}
    return heads


# --------------------------------------------------------------------------------------------
# One grid cell of the alignment stage
# --------------------------------------------------------------------------------------------


def parse_n_train(text: str | int) -> int | Literal["all"]:
    """A training size as written in config or a path: ``"all"`` or an integer >= 2."""
    if text == "all":
        return "all"
    try:
        n = int(text)
    except (TypeError, ValueError):
        n = -1
    if n < 2 or str(n) != str(text).strip():
        raise ValueError(f"n_train must be 'all' or an integer >= 2, got {text!r}")
    return n


def train_subset(
    train_ids: Sequence[str] | np.ndarray, n_train: int | str, seed: int
) -> np.ndarray:
    """The alignment-train rows of one cell: all train ids, or a seeded random subset of them.

    Ids are sorted first, so the result depends only on the set of ids, `n_train` and `seed`.
    For one seed the subsets are nested (the first n of one seeded permutation), so a larger
    N adds rows to a smaller one. Returned sorted.
    """
    ids = np.sort(np.asarray(list(train_ids), dtype=object))
    n = parse_n_train(n_train)
    if n == "all":
        return ids
    if n > ids.size:
        raise ValueError(
            f"n_train={n} but the train split has only {ids.size} rows; "
            "lower align.n_train or use 'all'"
        )
    order = np.random.default_rng(seed).permutation(ids.size)
    return np.sort(ids[order[:n]])


def cell_ids(
    splits: pd.DataFrame, *, corpus: str, n_train: int | str, seed: int
) -> dict[str, np.ndarray]:
    """train (cut to `n_train` by `train_subset`), val and test sample ids of one corpus."""
    out = {name: np.sort(ids_in_split(splits, name, corpus)) for name in ("train", "val", "test")}
    for name, ids in out.items():
        if ids.size == 0:
            raise ValueError(
                f"corpus {corpus!r} has no {name!r} rows in the split edge; alignment needs "
                "train, val (early stopping) and test (retrieval) rows: check config splits"
            )
    out["train"] = train_subset(out["train"], n_train, seed)
    return out


@dataclass
class CellFit:
    """What `fit_cell` returns: the fit, its test-split retrieval metrics, its curve table and
    the test rows' ranks (`sample_id`, `rank_v2t`, `rank_t2v`: what a bootstrap over the test
    rows resamples)."""

    result: AlignResult
    metrics: dict[str, Any]
    curve: pd.DataFrame
    ranks: pd.DataFrame


def fit_cell(
    vision: edges.Edge,
    tactile: edges.Edge,
    splits: pd.DataFrame,
    ids: dict[str, Sequence[str] | np.ndarray],
    *,
    tau: float,
    seed: int,
    settings: AlignSettings,
    rule: str = "train_heads",
    progress: Callable[[str], Any] | None = None,
) -> CellFit:
    """Train one alignment cell and evaluate it on held-out pairs (paper eq. 1, retrieval).

    vision, tactile: the corpus's feature edges (keyed by sample_id); `settings.feature`
    names the vector column both use (``vit`` or ``pixel``). ids: {"train", "val", "test"} sample ids
    (from `cell_ids`). The split guard runs first: `assert_trainable` refuses any train id not
    in the train split and any validation id not in the val split (validation rows only steer
    early stopping), naming the rule and the sample_id. Rows are joined on sample_id, never on
    order. `settings` is passed on to `fit_heads`.

    metrics: `paired_retrieval` of the projected test rows (top1/top5 both ways, median ranks,
    chance levels), n_test, n_train_rows, n_val, best-step validation loss, best_step,
    steps_run, stopped_early. curve: one row per evaluation, keyed by ``eval`` = "step~<k>".
    ranks: each test row's retrieval rank V→T and T→V (`retrieval_ranks`), keyed by sample_id.
    """
    train_ids = list(ids["train"])
    val_ids = list(ids["val"])
    test_ids = list(ids["test"])
    assert_trainable(train_ids, splits, rule=rule, allowed=("train",))
    assert_trainable(val_ids, splits, rule=rule, allowed=("val",))
    held = set(test_ids) & (set(train_ids) | set(val_ids))
    if held:
        raise ValueError(
            f"rule {rule}: sample_id {sorted(held)[0]!r} is both a test row and a training row"
        )
    feature = settings.feature
    for edge in (vision, tactile):
        if feature not in edge.vectors:
            raise edges.EdgeError(
                f"{edge.path}: no vector column {feature!r} (has: {sorted(edge.vectors)}); "
                "align.features must name a column of the feature edges"
            )
    fit_ids = train_ids + val_ids
    v = vision.subset(fit_ids).vectors[feature]
    t = tactile.subset(fit_ids).vectors[feature]
    n_tr = len(train_ids)
    result = fit_heads(
        v,
        t,
        np.arange(n_tr),
        np.arange(n_tr, len(fit_ids)),
        tau=tau,
        seed=seed,
        settings=settings,
        progress=progress,
    )
    z_v, z_t = project(
        result, vision.subset(test_ids).vectors[feature], tactile.subset(test_ids).vectors[feature]
    )
    retrieval = paired_retrieval(z_v, z_t)
    metrics: dict[str, Any] = {
        "budget": str(result.config["budget"]),
        "val_loss": float(result.best_val_loss),
        **{k: float(retrieval[k]) for k in _RETRIEVAL_KEYS},
        "n_test": int(retrieval["n"]),
        "n_train_rows": n_tr,
        "n_val": len(val_ids),
        "best_step": int(result.best_step),
        "steps_run": int(result.steps_run),
        "stopped_early": bool(result.stopped_early),
    }
    curve = pd.DataFrame(
        [
            {
                "eval": f"step~{int(c['step'])}",
                "step": int(c["step"]),
                "epoch": float(c["epoch"]),
                "lr": float(c["lr"]),
                "train_loss": np.nan if c["train_loss"] is None else float(c["train_loss"]),
                "val_loss": float(c["val_loss"]),
                "val_top1": float(c["val_top1"]),
            }
            for c in result.curve
        ]
    )
    ranks = pd.DataFrame(
        {
            "sample_id": test_ids,
            "rank_v2t": retrieval_ranks(z_v, z_t).astype(np.int64),
            "rank_t2v": retrieval_ranks(z_t, z_v).astype(np.int64),
        }
    )
    return CellFit(result=result, metrics=metrics, curve=curve, ranks=ranks)


_RETRIEVAL_KEYS = (*RETRIEVAL_METRICS, *CHANCE_COLUMNS)
