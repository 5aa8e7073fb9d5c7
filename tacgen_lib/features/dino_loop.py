"""The training loop of `dino.pretrain_dino`, step by step: the per-step schedules
(`DinoSchedules`), what the loop carries from step to step (`DinoRun`: student, teacher,
optimiser, the running centre and the step), one step (`dino_step`: multi-crop views, teacher
targets, student loss, optimiser step, teacher EMA and centre update) and one epoch with its
curve row (`dino_epoch`). The recipe is the `dino` module docstring's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor, nn

from tacgen_lib.features.augment import multi_crop
from tacgen_lib.features.dino_losses import (
    CURVE_MEANS,
    centre_and_sharpen,
    collapse_diagnostics,
    dino_cross_entropy,
    koleo_loss,
    sinkhorn_knopp,
)
from tacgen_lib.features.settings import DinoSettings
from tacgen_lib.optim import AdamW


@dataclass(frozen=True)
class DinoSchedules:
    """The per-step schedules of one run (float64, one value per step): learning rate, teacher
    EMA momentum and teacher temperature; the steps of an epoch, and how many first steps the
    head's last layer is frozen."""

    steps_per_epoch: int
    lr: np.ndarray
    momentum: np.ndarray
    teacher_temp: np.ndarray
    frozen_steps: int


@dataclass
class DinoRun:
    """What the DINO loop carries from step to step: the settings, student and teacher (each a
    backbone + `dino.DINOHead`, called as (CLS, logits)), the optimiser, the schedules, the
    device, the run's batch, global and local crop sizes, the running centre (``centre``
    centering: None until the first teacher batch) and the number of steps taken."""

    settings: DinoSettings
    student: nn.Module
    teacher: nn.Module
    opt: AdamW
    sched: DinoSchedules
    dev: torch.device
    batch_size: int
    image_size: int
    local_size: int
    center: Tensor | None = None
    step: int = 0


def _teacher_targets(run: DinoRun, views: list[Tensor], b: int) -> tuple[Tensor, Tensor, Tensor]:
    """(CLS, logits (2, b, K), targets) of the teacher on the two global crops: Sinkhorn-Knopp,
    or the running centre (set from the first teacher batch) and sharpening, at this step's
    teacher temperature."""
    s = run.settings
    t_temp = float(run.sched.teacher_temp[run.step])
    with torch.no_grad():
        t_cls, t_out = run.teacher(torch.cat(views[:2]))
        t_out = t_out.view(2, b, s.out_dim)
        if s.centering == "sinkhorn_knopp":
            p_t = sinkhorn_knopp(t_out, t_temp, s.sinkhorn_iterations)
        else:
            if run.center is None:
                run.center = t_out.mean(dim=(0, 1)).view(1, s.out_dim)
            p_t = centre_and_sharpen(t_out, run.center, t_temp)
    return t_cls, t_out, p_t


def _student_loss(
    run: DinoRun, views: list[Tensor], b: int, p_t: Tensor
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """(DINO cross-entropy, its entropy and KL terms, KoLeo, the loss trained on) of the student
    on every view against the teacher targets; KoLeo on the global crops' CLS features."""
    s = run.settings
    s_cls, s_glob = run.student(torch.cat(views[:2]))
    s_glob = s_glob.view(2, b, s.out_dim)
    if s.n_local_crops:
        s_loc = run.student(torch.cat(views[2:]))[1].view(s.n_local_crops, b, s.out_dim)
        s_out = torch.cat((s_glob, s_loc))
    else:
        s_out = s_glob
    loss, ent, kl = dino_cross_entropy(s_out, p_t, s.student_temp)
    koleo = sum(koleo_loss(c) for c in s_cls.view(2, b, -1))
    total_loss = loss + s.koleo_weight * koleo if s.koleo_weight else loss
    return loss, ent, kl, koleo, total_loss


def _student_update(run: DinoRun, total_loss: Tensor) -> None:
    """One optimiser step on `total_loss` at this step's learning rate; the head's last layer
    gets no gradient while frozen (DINO), then the gradient norm is clipped at `clip_grad`."""
    s = run.settings
    for g in run.opt.param_groups:
        g["lr"] = float(run.sched.lr[run.step])
    run.opt.zero_grad(set_to_none=True)
    total_loss.backward()
    if run.step < run.sched.frozen_steps:  # DINO: prototypes fixed while the rest settles
        for p in run.student.head.last_layer.parameters():
            p.grad = None
    if s.clip_grad:
        nn.utils.clip_grad_norm_(run.student.parameters(), s.clip_grad)
    run.opt.step()


def _teacher_update(
    run: DinoRun, t_cls: Tensor, t_out: Tensor, p_t: Tensor, b: int
) -> dict[str, float]:
    """The teacher's EMA step at this step's momentum and the running centre's update
    (``centre`` centering); returns the batch's `collapse_diagnostics`."""
    s = run.settings
    with torch.no_grad():
        m = float(run.sched.momentum[run.step])
        for ps, pt in zip(run.student.parameters(), run.teacher.parameters(), strict=True):
            pt.mul_(m).add_(ps.detach(), alpha=1 - m)
        if s.centering == "centre":
            batch_center = t_out.mean(dim=(0, 1)).view(1, s.out_dim)
            run.center = run.center * s.center_momentum + batch_center * (1 - s.center_momentum)
        return collapse_diagnostics(p_t, t_cls.view(2, b, -1))


def dino_step(
    run: DinoRun,
    batch: Tensor,
    gen: torch.Generator,
    epoch: int,
    bi: int,
    sums: dict[str, float],
) -> None:
    """One DINO step on a batch of frames: its multi-crop views (drawn from `gen`), teacher
    targets, student loss, optimiser step and teacher update; the step's terms are added to
    `sums` (`dino_losses.CURVE_MEANS`). A non-finite loss stops the run."""
    s = run.settings
    views = multi_crop(
        batch,
        gen,
        global_size=run.image_size,
        local_size=run.local_size,
        n_local=s.n_local_crops,
        jitter=s.jitter,
    )
    views = [v.to(run.dev) for v in views]
    b = batch.shape[0]
    t_cls, t_out, p_t = _teacher_targets(run, views, b)
    loss, ent, kl, koleo, total_loss = _student_loss(run, views, b, p_t)
    if not torch.isfinite(total_loss):
        raise FloatingPointError(
            f"pretrain_dino: non-finite loss at epoch {epoch} step {bi}; lower lr "
            f"(now {run.sched.lr[run.step]:.2e}) or check the frames"
        )
    _student_update(run, total_loss)
    diag = _teacher_update(run, t_cls, t_out, p_t, b)
    sums["loss"] += loss.item()
    sums["teacher_entropy"] += ent.item()
    sums["kl"] += kl.item()
    sums["koleo"] += float(koleo.detach())
    for key, val in diag.items():
        sums[key] += val
    run.step += 1


def dino_epoch(
    run: DinoRun,
    data: Tensor,
    order_rng: np.random.Generator,
    gen: torch.Generator,
    epoch: int,
) -> dict[str, float]:
    """One epoch over the frames `data` in an order drawn from `order_rng` (the last incomplete
    batch dropped); its curve row: the epoch, the means of its steps' terms, the last step's
    lr, momentum and teacher temperature, and its seconds."""
    t0 = time.perf_counter()
    perm = order_rng.permutation(data.shape[0])
    sums = dict.fromkeys(CURVE_MEANS, 0.0)
    run.student.train()
    steps_per_epoch, batch_size = run.sched.steps_per_epoch, run.batch_size
    for bi in range(steps_per_epoch):
        idx = torch.from_numpy(perm[bi * batch_size : (bi + 1) * batch_size])
        dino_step(run, data[idx], gen, epoch, bi, sums)
    row = {"epoch": float(epoch + 1)}
    row |= {key: val / steps_per_epoch for key, val in sums.items()}
    row |= {
        "lr": float(run.sched.lr[run.step - 1]),
        "momentum": float(run.sched.momentum[run.step - 1]),
        "teacher_temp": float(run.sched.teacher_temp[run.step - 1]),
        "seconds": time.perf_counter() - t0,
    }
    return row
