"""DINO self-distillation pretraining of a per-modality ViT backbone (in-workflow, CPU).

This module owns the DINO recipe (Caron et al. 2021, as used for DINOv2's image-level loss):
a student and a teacher of the same architecture (tacgen_lib.vit backbone + DINO projection
head); the teacher is an exponential moving average (EMA) of the student; the teacher's
outputs are centred (running mean, momentum 0.9) and sharpened (teacher temperature below
the student's); the student sees 2 global + a few local crops, the teacher only the 2 global
crops; the loss is the cross-entropy between the teacher distribution of one view and the
student distribution of every other view.

Augmentations are torch-only and batched (no torchvision): random resized crop and horizontal
flip as one affine resampling (`F.affine_grid` + `F.grid_sample`, reflection padding), then
colour jitter (brightness, contrast, saturation; p=0.8) and random greyscale (p=0.2), all
drawn from one seeded `torch.Generator`. Gaussian blur, solarisation and hue jitter of the
original recipe are left out (cost on CPU; hue is meaningless for tactile shading).

Determinism: weights are initialised under a forked RNG seeded with `seed`, the epoch order
comes from numpy's Generator(seed) and augmentations from torch.Generator(seed), and the loop
runs with torch.use_deterministic_algorithms(True) (restored afterwards). Same images + same
arguments + same torch build and thread count => bit-identical weights and curve on CPU.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from tacgen_lib.features import imagenet_normalise, to_unit_tensor
from tacgen_lib.vit import PATCH_SIZE, DinoVisionTransformer, build_vit

__all__ = [
    "DINOHead",
    "PretrainResult",
    "dino_loss",
    "dino_loss_terms",
    "multi_crop",
    "pretrain_dino",
]


class DINOHead(nn.Module):
    """DINO projection head: 3-layer MLP (GELU) -> l2-normalise -> weight-normalised linear.

    The last layer's rows are unit-normalised at every forward (DINO's norm_last_layer, with the
    weight-norm gain fixed to 1), so its output is a cosine similarity to `out_dim` prototypes.
    """

    def __init__(self, in_dim: int, out_dim: int, hidden_dim: int, bottleneck_dim: int) -> None:
        super().__init__()
        self.mlp = nn.Sequential(
            nn.Linear(in_dim, hidden_dim),
            nn.GELU(),
            nn.Linear(hidden_dim, hidden_dim),
            nn.GELU(),
            nn.Linear(hidden_dim, bottleneck_dim),
        )
        for m in self.mlp:
            if isinstance(m, nn.Linear):
                nn.init.trunc_normal_(m.weight, std=0.02)
                nn.init.zeros_(m.bias)
        self.last_layer = nn.Linear(bottleneck_dim, out_dim, bias=False)

    def forward(self, x: Tensor) -> Tensor:
        x = F.normalize(self.mlp(x), dim=-1, eps=1e-12)
        return F.linear(x, F.normalize(self.last_layer.weight, dim=1, eps=1e-12))


class _Net(nn.Module):
    """Backbone (CLS token) followed by the DINO head."""

    def __init__(self, backbone: DinoVisionTransformer, head: DINOHead) -> None:
        super().__init__()
        self.backbone = backbone
        self.head = head

    def forward(self, x: Tensor) -> Tensor:
        return self.head(self.backbone(x))


def dino_loss_terms(
    student_out: Tensor,
    teacher_out: Tensor,
    center: Tensor,
    student_temp: float,
    teacher_temp: float,
) -> tuple[Tensor, Tensor, Tensor]:
    """DINO cross-entropy with its two parts: (loss, teacher entropy, KL(teacher || student)).

    student_out: (S, B, K) student logits for S crops, the first T of which are the global
    crops the teacher saw; teacher_out: (T, B, K) teacher logits; center: (K,) or (1, K).
    The teacher distribution is softmax((teacher - center) / teacher_temp); the student's is
    log_softmax(student / student_temp). The loss averages -sum_k p_t log p_s over all
    (teacher crop t, student crop s) pairs with s != t and over the batch; entropy and KL are
    averaged the same way (loss = entropy + KL). Log-sum-exp throughout, so constant,
    identical or single-sample batches and large logits stay finite.
    """
    if student_out.ndim != 3 or teacher_out.ndim != 3:
        raise ValueError(
            f"dino_loss: expected (crops, batch, K) logits, got student {tuple(student_out.shape)}"
            f" and teacher {tuple(teacher_out.shape)}"
        )
    n_s, b, k = student_out.shape
    n_t = teacher_out.shape[0]
    if teacher_out.shape[1:] != (b, k) or n_t > n_s:
        raise ValueError(
            f"dino_loss: teacher {tuple(teacher_out.shape)} does not match student "
            f"{tuple(student_out.shape)} (need same batch and K, teacher crops <= student crops)"
        )
    if not (0 < teacher_temp and 0 < student_temp):
        raise ValueError(f"dino_loss: temperatures must be > 0, got {student_temp}, {teacher_temp}")
    pair_mask = torch.ones(n_t, n_s, dtype=torch.bool)
    pair_mask[torch.arange(n_t), torch.arange(n_t)] = False
    if not pair_mask.any():
        raise ValueError("dino_loss: need at least one student crop the teacher did not see")
    log_p_t = F.log_softmax((teacher_out - center.reshape(1, 1, k)) / teacher_temp, dim=-1)
    p_t = log_p_t.exp()
    log_p_s = F.log_softmax(student_out / student_temp, dim=-1)
    # cross-entropy for every (teacher crop, student crop) pair, averaged over the batch
    ce = -torch.einsum("tbk,sbk->ts", p_t, log_p_s) / b
    entropy_t = -(p_t * log_p_t).sum(-1).mean(-1)  # (T,)
    n_pairs = pair_mask.sum()
    loss = ce[pair_mask].sum() / n_pairs
    entropy = (entropy_t[:, None].expand(n_t, n_s)[pair_mask]).sum() / n_pairs
    return loss, entropy, loss - entropy


def dino_loss(
    student_out: Tensor,
    teacher_out: Tensor,
    center: Tensor,
    student_temp: float,
    teacher_temp: float,
) -> Tensor:
    """DINO self-distillation loss (see `dino_loss_terms` for shapes and definition)."""
    return dino_loss_terms(student_out, teacher_out, center, student_temp, teacher_temp)[0]


def _random_resized_crop(
    x: Tensor, size: int, scale: tuple[float, float], gen: torch.Generator
) -> Tensor:
    """Per-image random resized crop (area fraction in `scale`, aspect 3/4..4/3) + h-flip."""
    b = x.shape[0]
    u = torch.rand(b, 6, generator=gen, dtype=torch.float64)
    area = scale[0] + (scale[1] - scale[0]) * u[:, 0]
    log_ratio = math.log(3 / 4) + (math.log(4 / 3) - math.log(3 / 4)) * u[:, 1]
    ratio = torch.exp(log_ratio)
    cw = torch.sqrt(area * ratio).clamp(max=1.0)  # crop width / image width
    ch = torch.sqrt(area / ratio).clamp(max=1.0)
    cx = (1 - cw) * (2 * u[:, 2] - 1)  # crop centre in [-1, 1] coordinates
    cy = (1 - ch) * (2 * u[:, 3] - 1)
    flip = torch.where(u[:, 4] < 0.5, -1.0, 1.0).to(torch.float64)
    theta = torch.zeros(b, 2, 3, dtype=torch.float64)
    theta[:, 0, 0] = cw * flip
    theta[:, 0, 2] = cx
    theta[:, 1, 1] = ch
    theta[:, 1, 2] = cy
    grid = F.affine_grid(theta.to(x.dtype), [b, 3, size, size], align_corners=False)
    return F.grid_sample(x, grid, mode="bilinear", padding_mode="reflection", align_corners=False)


def _colour_jitter(x: Tensor, gen: torch.Generator, strength: float) -> Tensor:
    """Brightness, contrast, saturation jitter (p=0.8) then random greyscale (p=0.2)."""
    b = x.shape[0]
    u = torch.rand(b, 5, generator=gen)
    on = (u[:, 0] < 0.8).view(b, 1, 1, 1)
    bright = (1 + strength * (2 * u[:, 1] - 1)).view(b, 1, 1, 1)
    contrast = (1 + strength * (2 * u[:, 2] - 1)).view(b, 1, 1, 1)
    sat = (1 + strength * (2 * u[:, 3] - 1)).view(b, 1, 1, 1)
    lum_w = torch.tensor([0.299, 0.587, 0.114], dtype=x.dtype).view(1, 3, 1, 1)
    y = (x * bright).clamp(0, 1)
    mean = (y * lum_w).sum(1, keepdim=True).mean((2, 3), keepdim=True)
    y = ((y - mean) * contrast + mean).clamp(0, 1)
    grey = (y * lum_w).sum(1, keepdim=True)
    y = ((y - grey) * sat + grey).clamp(0, 1)
    y = torch.where(on, y, x)
    to_grey = (u[:, 4] < 0.2).view(b, 1, 1, 1)
    return torch.where(to_grey, (y * lum_w).sum(1, keepdim=True).expand_as(y), y)


def multi_crop(
    x: Tensor,
    gen: torch.Generator,
    *,
    global_size: int,
    local_size: int,
    n_local: int,
    global_scale: tuple[float, float] = (0.4, 1.0),
    local_scale: tuple[float, float] = (0.05, 0.4),
    jitter: float = 0.4,
) -> list[Tensor]:
    """DINO multi-crop of a batch (B, 3, H, W) in [0, 1]: 2 global then n_local local views.

    Each view is ImageNet-normalised and ready for the backbone.
    """
    views = []
    for i in range(2 + n_local):
        size, scale = (global_size, global_scale) if i < 2 else (local_size, local_scale)
        v = _colour_jitter(_random_resized_crop(x, size, scale, gen), gen, jitter)
        views.append(imagenet_normalise(v))
    return views


@dataclass
class PretrainResult:
    """Outcome of `pretrain_dino`.

    backbone_state: the teacher backbone's weights in official DINOv2 key format (what DINO
    evaluates; save with torch.save or vit.save_backbone after `backbone()`).
    curve: one dict per epoch: epoch, loss, teacher_entropy, kl, lr, momentum, seconds.
    """

    arch: str
    image_size: int
    backbone_state: dict[str, Tensor]
    curve: list[dict[str, float]] = field(default_factory=list)

    def backbone(self) -> DinoVisionTransformer:
        """A ViT of `arch` (pos grid image_size / 14) carrying the pretrained teacher weights."""
        model = build_vit(self.arch, img_size=self.image_size)
        model.load_state_dict(self.backbone_state, strict=True)
        return model.eval()


def _cosine(start: float, end: float, n: int) -> np.ndarray:
    if n <= 1:
        return np.full(max(n, 0), start, dtype=np.float64)
    return end + 0.5 * (start - end) * (1 + np.cos(np.pi * np.arange(n) / (n - 1)))


def pretrain_dino(
    images: np.ndarray,
    *,
    arch: str,
    image_size: int,
    epochs: int,
    batch_size: int,
    lr: float,
    seed: int,
    progress: Callable[[str], None] | None = None,
    n_local_crops: int = 4,
    local_size: int | None = None,
    out_dim: int = 1024,
    hidden_dim: int = 512,
    bottleneck_dim: int = 128,
    student_temp: float = 0.1,
    teacher_temp: float = 0.04,
    center_momentum: float = 0.9,
    momentum_teacher: float = 0.99,
    weight_decay: float = 0.04,
    warmup_epochs: int = 1,
    clip_grad: float = 3.0,
    jitter: float = 0.4,
) -> PretrainResult:
    """Pretrain a backbone of `arch` on uint8 frames (N, H, W, 3) with DINO; see module doc.

    Frames are resized once to image_size x image_size (features.to_unit_tensor); global crops
    are image_size, local crops `local_size` (default: the multiple of 14 nearest 3/7 of
    image_size, at least 28). Optimiser: AdamW (no decay on biases, norms, LayerScale and
    tokens), lr linear warm-up over `warmup_epochs` then cosine to lr/100, gradient-norm
    clipping at `clip_grad`; teacher EMA momentum cosine from `momentum_teacher` to 1 (0.99
    rather than DINO's 0.996, as runs here have hundreds, not 100k+, steps). The centre starts
    at the first teacher batch's mean, not at zero: from zero, the first ~20 steps (momentum
    0.9) would sharpen the component all frames share into one constant target for every
    image, which is a push towards collapse in a run of only ~100 steps.
    The last incomplete batch of each epoch is dropped, so every step has the same batch size
    (the order is reshuffled every epoch, so all frames are seen); batch_size is capped at N.

    CPU threads: set torch.set_num_threads(...) to the cores the job owns. On an oversubscribed
    machine 2 OpenMP threads were measured ~5x slower than 1 (spin-waits). Bit-identical
    reruns need the same thread count.
    """
    if images.ndim != 4 or images.shape[3] != 3 or images.dtype != np.uint8:
        raise ValueError(
            f"pretrain_dino: expected uint8 frames (N, H, W, 3), got {images.dtype} {images.shape}"
        )
    if image_size % PATCH_SIZE:
        raise ValueError(
            f"pretrain_dino: image_size {image_size} is not a multiple of {PATCH_SIZE}"
        )
    n = images.shape[0]
    batch_size = min(batch_size, n)
    if batch_size < 1 or epochs < 1:
        raise ValueError(f"pretrain_dino: need batch_size >= 1 and epochs >= 1 (n={n})")
    if local_size is None:
        local_size = max(2 * PATCH_SIZE, round(image_size * 3 / 7 / PATCH_SIZE) * PATCH_SIZE)
    if local_size % PATCH_SIZE:
        raise ValueError(
            f"pretrain_dino: local_size {local_size} is not a multiple of {PATCH_SIZE}"
        )
    say = progress or (lambda _msg: None)

    det_before = torch.are_deterministic_algorithms_enabled()
    fill_before = torch.utils.deterministic.fill_uninitialized_memory
    torch.use_deterministic_algorithms(True)
    # No op here reads uninitialised memory; NaN-filling every torch.empty costs ~15% of a step.
    torch.utils.deterministic.fill_uninitialized_memory = False
    try:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            backbone = build_vit(arch, img_size=image_size)
            head = DINOHead(backbone.embed_dim, out_dim, hidden_dim, bottleneck_dim)
            student = _Net(backbone, head)
        teacher = copy.deepcopy(student)
        for p in teacher.parameters():
            p.requires_grad_(False)

        # resized once, in chunks, so large raw frames never sit in memory as float32
        data = torch.cat(
            [to_unit_tensor(images[i : i + 256], image_size) for i in range(0, n, 256)]
        )
        order_rng = np.random.default_rng(seed)
        gen = torch.Generator().manual_seed(seed)

        decay = [p for nm, p in student.named_parameters() if p.ndim > 1 and "token" not in nm]
        no_decay = [
            p for nm, p in student.named_parameters() if not (p.ndim > 1 and "token" not in nm)
        ]
        # pos_embed has ndim 3: keep it out of weight decay too (DINO does not decay it)
        decay = [p for p in decay if p is not student.backbone.pos_embed]
        no_decay.append(student.backbone.pos_embed)
        opt = torch.optim.AdamW(
            [
                {"params": decay, "weight_decay": weight_decay},
                {"params": no_decay, "weight_decay": 0.0},
            ],
            lr=lr,
        )
        steps_per_epoch = max(1, n // batch_size)
        total = steps_per_epoch * epochs
        warm = min(total, warmup_epochs * steps_per_epoch)
        lr_sched = np.concatenate(
            [np.linspace(lr / max(warm, 1), lr, warm), _cosine(lr, lr / 100, total - warm)]
        )
        mom_sched = _cosine(momentum_teacher, 1.0, total)
        center: Tensor | None = None  # set from the first teacher batch (see docstring)

        curve: list[dict[str, float]] = []
        step = 0
        for epoch in range(epochs):
            t0 = time.perf_counter()
            perm = order_rng.permutation(n)
            sums = np.zeros(3)
            student.train()
            for bi in range(steps_per_epoch):
                idx = torch.from_numpy(perm[bi * batch_size : (bi + 1) * batch_size])
                views = multi_crop(
                    data[idx],
                    gen,
                    global_size=image_size,
                    local_size=local_size,
                    n_local=n_local_crops,
                    jitter=jitter,
                )
                b = idx.shape[0]
                with torch.no_grad():
                    t_out = teacher(torch.cat(views[:2])).view(2, b, out_dim)
                    if center is None:
                        center = t_out.mean(dim=(0, 1)).view(1, out_dim)
                s_glob = student(torch.cat(views[:2])).view(2, b, out_dim)
                if n_local_crops:
                    s_loc = student(torch.cat(views[2:])).view(n_local_crops, b, out_dim)
                    s_out = torch.cat((s_glob, s_loc))
                else:
                    s_out = s_glob
                loss, ent, kl = dino_loss_terms(s_out, t_out, center, student_temp, teacher_temp)
                if not torch.isfinite(loss):
                    raise FloatingPointError(
                        f"pretrain_dino: non-finite loss at epoch {epoch} step {bi}; lower lr "
                        f"(now {lr_sched[step]:.2e}) or check the frames"
                    )
                for g in opt.param_groups:
                    g["lr"] = float(lr_sched[step])
                opt.zero_grad(set_to_none=True)
                loss.backward()
                if clip_grad:
                    nn.utils.clip_grad_norm_(student.parameters(), clip_grad)
                opt.step()
                with torch.no_grad():
                    m = float(mom_sched[step])
                    for ps, pt in zip(student.parameters(), teacher.parameters(), strict=True):
                        pt.mul_(m).add_(ps.detach(), alpha=1 - m)
                    batch_center = t_out.mean(dim=(0, 1)).view(1, out_dim)
                    center = center * center_momentum + batch_center * (1 - center_momentum)
                sums += (loss.item(), ent.item(), kl.item())
                step += 1
            mean = sums / steps_per_epoch
            row = {
                "epoch": float(epoch + 1),
                "loss": float(mean[0]),
                "teacher_entropy": float(mean[1]),
                "kl": float(mean[2]),
                "lr": float(lr_sched[step - 1]),
                "momentum": float(mom_sched[step - 1]),
                "seconds": time.perf_counter() - t0,
            }
            curve.append(row)
            say(
                f"dino epoch {epoch + 1}/{epochs}: loss {row['loss']:.4f} "
                f"H(teacher) {row['teacher_entropy']:.3f} KL {row['kl']:.4f} "
                f"({row['seconds']:.1f}s)"
            )
    finally:
        torch.use_deterministic_algorithms(det_before)
        torch.utils.deterministic.fill_uninitialized_memory = fill_before

    state = {k: v.detach().clone() for k, v in teacher.backbone.state_dict().items()}
    return PretrainResult(arch=arch, image_size=image_size, backbone_state=state, curve=curve)
