"""Training the alignment heads: `fit_heads` (AdamW, a cosine schedule with linear warm-up
`cosine_warmup_lr`, gradient clipping, early stopping on the held-out validation loss keeping the
best weights, seeded shuffling, bit-for-bit reproducible on CPU for a given seed and thread
count) with two budgets, ``"epochs"`` and ``"steps"``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import Tensor

from tacgen_lib.align.heads import (
    AlignHeads,
    AlignResult,
    as_features,
)
from tacgen_lib.align.loss import info_nce
from tacgen_lib.align.retrieval import (
    paired_retrieval,
)
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.optim import AdamW


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

    Fused AdamW is several times cheaper per step than the foreach variant on CPU and is
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
    """The heads' weights, copied to the CPU (where they are saved)."""
    return {
        "vision": {k: v.detach().cpu().clone() for k, v in heads.vision.state_dict().items()},
        "tactile": {k: v.detach().cpu().clone() for k, v in heads.tactile.state_dict().items()},
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
    metrics = paired_retrieval(torch.cat(zs_v).cpu().numpy(), torch.cat(zs_t).cpu().numpy())
    top1 = 0.5 * (metrics["top1_v2t"] + metrics["top1_t2v"])
    return loss_sum / val_idx.size, top1


def _checked_inputs(
    v: np.ndarray | Tensor,
    t: np.ndarray | Tensor,
    train_idx: Sequence[int] | np.ndarray,
    val_idx: Sequence[int] | np.ndarray,
    tau: float,
    s: AlignSettings,
) -> tuple[Tensor, Tensor, np.ndarray, np.ndarray]:
    """(V, T, train positions, validation positions) as `fit_heads` trains on them, after
    checking that V and T pair the same rows, the positions are disjoint, the training rows
    give in-batch negatives, and the budget, batch, evaluation, patience and tau are usable."""
    v_t = as_features(v, "fit_heads: vision features v")
    t_t = as_features(t, "fit_heads: tactile features t")
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
    if s.budget not in ("epochs", "steps"):
        raise ValueError(f"fit_heads: budget must be 'epochs' or 'steps', got {s.budget!r}")
    for name, val, low in (("batch_size", s.batch_size, 2), ("eval_every", s.eval_every, 1)):
        if int(val) != val or val < low:
            raise ValueError(f"fit_heads: {name} must be an integer >= {low}, got {val!r}")
    if s.patience < 0:
        raise ValueError(f"fit_heads: patience must be >= 0 (0 disables), got {s.patience}")
    if not (math.isfinite(tau) and tau > 0):
        raise ValueError(f"fit_heads: tau must be > 0, got {tau!r}")
    return v_t, t_t, tr, va


def _total_steps(s: AlignSettings, steps_per_epoch: int) -> int:
    """The run's number of steps under its budget (``"epochs"`` or ``"steps"``)."""
    if s.budget == "epochs":
        if s.epochs < 1:
            raise ValueError(f"fit_heads: budget 'epochs' needs epochs >= 1, got {s.epochs}")
        return int(s.epochs) * steps_per_epoch
    if s.steps < 1:
        raise ValueError(f"fit_heads: budget 'steps' needs steps >= 1, got {s.steps}")
    return int(s.steps)


def _run_config(
    s: AlignSettings, *, tau: float, seed: int, bsz: int, n_train: int, n_val: int
) -> dict:
    """The run's configuration as `AlignResult.config` records it (the batch as used)."""
    return {
        "tau": float(tau),
        "seed": int(seed),
        "budget": s.budget,
        "epochs": int(s.epochs),
        "steps": int(s.steps),
        "batch_size": bsz,
        "lr": float(s.lr),
        "weight_decay": float(s.weight_decay),
        "warmup_frac": float(s.warmup_frac),
        "clip_grad": float(s.clip_grad),
        "patience": int(s.patience),
        "eval_every": int(s.eval_every),
        "n_train": int(n_train),
        "n_val": int(n_val),
    }


@dataclass
class _Tracker:
    """What training carries from one validation evaluation to the next: the heads, the
    features and validation rows it evaluates on, the curve, the best weights with their
    validation loss and step, the evaluations without improvement since, and the running train
    loss since the last evaluation."""

    heads: AlignHeads
    v: Tensor
    t: Tensor
    val_idx: np.ndarray
    tau: float
    batch_size: int
    steps_per_epoch: int
    total: int
    patience: int
    progress: Callable[[str], Any] | None
    best_state: dict[str, dict[str, Tensor]]
    curve: list[dict[str, float | None]] = field(default_factory=list)
    best_loss: float = math.inf
    best_step: int = 0
    bad_evals: int = 0
    running: float = 0.0
    running_n: int = 0

    def record(self, step: int, lr_now: float) -> bool:
        """Evaluate; returns True when early stopping should fire."""
        val_loss, val_top1 = _evaluate(
            self.heads, self.v, self.t, self.val_idx, self.tau, self.batch_size
        )
        train_loss = self.running / self.running_n if self.running_n else None
        self.running, self.running_n = 0.0, 0
        epoch = step / self.steps_per_epoch
        self.curve.append(
            {
                "step": step,
                "epoch": epoch,
                "lr": lr_now,
                "train_loss": train_loss,
                "val_loss": val_loss,
                "val_top1": val_top1,
            }
        )
        if val_loss < self.best_loss:
            self.best_loss, self.best_step, self.bad_evals = val_loss, step, 0
            self.best_state = _state_copy(self.heads)
        else:
            self.bad_evals += 1
        if self.progress is not None:
            self.progress(
                f"align step {step}/{self.total} epoch {epoch:.2f} "
                f"lr {lr_now:.3g} train_loss {'-' if train_loss is None else f'{train_loss:.4f}'} "
                f"val_loss {val_loss:.4f} "
                f"val_top1 {val_top1:.4f} best_step {self.best_step}"
            )
        return self.patience > 0 and self.bad_evals >= self.patience


def _train(
    track: _Tracker,
    opt: AdamW,
    tr: np.ndarray,
    rng: np.random.Generator,
    s: AlignSettings,
) -> tuple[int, bool]:
    """The training steps after the first evaluation: each epoch a fresh permutation of the
    train rows (from `rng`) cut into full batches, `train_step` at the `cosine_warmup_lr` of
    the step, an evaluation every `eval_every` steps and at the last; (steps run, whether
    early stopping fired)."""
    heads, bsz, total, steps_per_epoch = (
        track.heads,
        track.batch_size,
        track.total,
        track.steps_per_epoch,
    )
    order = np.empty(0, dtype=np.int64)
    step = 0
    while step < total:
        pos = step % steps_per_epoch
        if pos == 0:
            order = tr[rng.permutation(tr.size)]
        ix = torch.from_numpy(order[pos * bsz : (pos + 1) * bsz])
        lr_now = cosine_warmup_lr(step, total, s.lr, s.warmup_frac)
        loss = train_step(
            heads, opt, track.v[ix], track.t[ix], tau=track.tau, lr=lr_now, clip_grad=s.clip_grad
        )
        if not math.isfinite(loss):
            raise FloatingPointError(
                f"fit_heads: training loss became {loss} at step {step} "
                f"(tau={track.tau}, lr={lr_now:.3g}); lower lr or raise tau"
            )
        track.running += loss
        track.running_n += 1
        step += 1
        if step % s.eval_every == 0 or step == total:
            if track.record(step, lr_now) and step < total:
                return step, True
    return step, False


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
    device: torch.device | str,
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

    device: where the heads train (`tacgen_lib.runtime.device`): initialised on the CPU, then
    moved with the features; the weights come back on the CPU. On a GPU the result agrees
    with the CPU's within float tolerance, not bit for bit.
    """
    started = time.perf_counter()
    s = settings
    v_t, t_t, tr, va = _checked_inputs(v, t, train_idx, val_idx, tau, s)
    bsz = min(int(s.batch_size), tr.size)
    steps_per_epoch = tr.size // bsz
    total = _total_steps(s, steps_per_epoch)

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        heads = AlignHeads(v_t.shape[1], t_t.shape[1])
    # on the CPU no move at all: the same tensors, the same bytes
    dev = torch.device(device)
    heads.to(dev)
    v_t, t_t = v_t.to(dev), t_t.to(dev)
    heads.train()
    opt = make_optimizer(heads, lr=s.lr, weight_decay=s.weight_decay)
    rng = np.random.default_rng(seed)
    config = _run_config(s, tau=tau, seed=seed, bsz=bsz, n_train=tr.size, n_val=va.size)
    track = _Tracker(
        heads=heads,
        v=v_t,
        t=t_t,
        val_idx=va,
        tau=tau,
        batch_size=bsz,
        steps_per_epoch=steps_per_epoch,
        total=total,
        patience=s.patience,
        progress=progress,
        best_state=_state_copy(heads),
    )
    track.record(0, 0.0)
    step, stopped_early = _train(track, opt, tr, rng, s)
    return AlignResult(
        heads=track.best_state,
        dims=heads.dims(),
        config=config,
        curve=track.curve,
        best_step=track.best_step,
        best_val_loss=track.best_loss,
        steps_run=step,
        total_steps=total,
        stopped_early=stopped_early,
        seconds=time.perf_counter() - started,
    )
