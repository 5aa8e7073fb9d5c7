"""DINO self-distillation pretraining of a per-modality ViT backbone (in-workflow, CPU).

The DINO recipe (Caron et al. 2021) with DINOv2's image-level safeguards
(Oquab et al. 2023): a student and a teacher of the same architecture (tacgen_lib.features.vit backbone +
DINO projection head); the teacher is an exponential moving average (EMA) of the student; the
teacher's logits are turned into targets by Sinkhorn-Knopp centring (`sinkhorn_knopp`, DINOv2)
or, as in DINO v1, by subtracting a running centre (momentum 0.9) and sharpening (teacher
temperature below the student's); the student sees 2 global + a few local crops, the teacher
only the 2 global crops; the loss is the cross-entropy between the teacher target of one view
and the student distribution of every other view, plus the KoLeo regulariser on the student's
CLS features of each global crop (`koleo_loss`, DINOv2, weight 0.1); the prototypes (the head's
last layer) are frozen during the first epoch (DINO). `collapse_diagnostics` reads both
collapses off every batch (per-sample vs batch-mean target entropy, CLS cosine).

Why SK + KoLeo: with the running centre, runs of ~100 steps on the simulated corpus collapsed
(one prototype for every frame, then uniform targets: per-sample and batch-mean entropy both
-> ln K, teacher CLS cosine 0.95). SK makes every prototype take an equal share of each batch,
so the one-prototype collapse is impossible and a lower teacher temperature is safe; KoLeo
keeps the CLS features of a batch apart, so SK cannot be satisfied by a constant feature.

Augmentations are torch-only and batched (no torchvision): random resized crop and horizontal
flip as one affine resampling (`F.affine_grid` + `F.grid_sample`, reflection padding), then
colour jitter (brightness, contrast, saturation; p=0.8) and random greyscale (p=0.2), all
drawn from one seeded `torch.Generator`. Gaussian blur, solarisation and hue jitter of the
original recipe are left out (cost on CPU; hue is meaningless for tactile shading).

Determinism: weights are initialised under a forked RNG seeded with `seed`, the epoch order
comes from numpy's Generator(seed) and augmentations from torch.Generator(seed), and the loop
runs in torch's deterministic-algorithms mode (`deterministic_algorithms`, restored afterwards).
Same images + same arguments + same torch build and thread count => bit-identical weights and
curve on CPU.

The losses and the collapse diagnostics live in `dino_losses`, the multi-crop augmentation in
`augment`, the loop's steps in `dino_loop`; this module holds the head and the run
(`pretrain_dino`: its checks, networks, optimiser and schedules).
"""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from tacgen_lib.features.dino_loop import DinoRun, DinoSchedules, dino_epoch
from tacgen_lib.features.extract import check_train_frames, to_unit_tensor
from tacgen_lib.features.settings import DinoSettings
from tacgen_lib.features.vit import PATCH_SIZE, DinoVisionTransformer, build_vit
from tacgen_lib.optim import AdamW


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

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """(CLS features (B, D), head logits (B, K))."""
        cls = self.backbone(x)
        return cls, self.head(cls)


@dataclass
class PretrainResult:
    """Outcome of `pretrain_dino`.

    backbone_state: the teacher backbone's weights in official DINOv2 key format (what DINO
    evaluates; save with torch.save or vit_checkpoint.save_backbone after `backbone()`).
    curve: one dict per epoch (means over its steps): epoch, loss (DINO cross-entropy),
    teacher_entropy (per-sample), kl, koleo, teacher_batch_entropy, teacher_cls_cosine (see
    `collapse_diagnostics`), then the last step's lr, momentum, teacher_temp, and seconds.
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


def cosine_schedule(start: float, end: float, n: int) -> np.ndarray:
    """n values from `start` to `end` along a half cosine (float64; one value: `start`)."""
    if n <= 1:
        return np.full(max(n, 0), start, dtype=np.float64)
    return end + 0.5 * (start - end) * (1 + np.cos(np.pi * np.arange(n) / (n - 1)))


def warmup_cosine_lr(lr: float, warm: int, total: int) -> np.ndarray:
    """The learning rate of each of `total` steps (float64): a linear warm-up from lr/warm to
    `lr` over the first `warm` steps, then `cosine_schedule` from `lr` to lr/100 (DINO's and
    SimCLR's schedule)."""
    return np.concatenate(
        [np.linspace(lr / max(warm, 1), lr, warm), cosine_schedule(lr, lr / 100, total - warm)]
    )


@contextlib.contextmanager
def deterministic_algorithms(warn_only: bool = False) -> Iterator[None]:
    """torch's deterministic-algorithms mode inside the block, the previous mode (and its
    warn-only setting) restored after; uninitialised memory is not NaN-filled inside (no op of
    pretraining reads it, and filling every `torch.empty` costs ~15% of a step). `warn_only`
    (a GPU run): an op without a deterministic kernel warns instead of stopping.

    It sets the eager flag `torch.use_deterministic_algorithms` sets
    (`torch._C._set_deterministic_algorithms`) and not the function's other effect, the
    `deterministic` option of TorchInductor: setting that option imports torch._inductor and
    torch._dynamo (~800 modules, ~2 s per process on the slower CPU class) for compiled graphs,
    and nothing here is compiled. `tests/features/test_dino.py` checks the mode inside and the
    restore, and that pretraining imports neither.
    """
    before = torch.are_deterministic_algorithms_enabled()
    warn_only_before = torch.is_deterministic_algorithms_warn_only_enabled()
    fill_before = torch.utils.deterministic.fill_uninitialized_memory
    torch._C._set_deterministic_algorithms(True, warn_only=warn_only)
    torch.utils.deterministic.fill_uninitialized_memory = False
    try:
        yield
    finally:
        torch._C._set_deterministic_algorithms(before, warn_only=warn_only_before)
        torch.utils.deterministic.fill_uninitialized_memory = fill_before


def _checked_sizes(images: np.ndarray, s: DinoSettings, image_size: int) -> tuple[int, int]:
    """(batch size, local crop size) of a run: the batch capped at the number of frames, the
    local size `pretrain_dino`'s default where unset; after checking the frames, the sizes
    against the patch, the centering and the regularisers' signs."""
    check_train_frames(images, "pretrain_dino")
    if image_size % PATCH_SIZE:
        raise ValueError(
            f"pretrain_dino: image_size {image_size} is not a multiple of {PATCH_SIZE}"
        )
    n = images.shape[0]
    batch_size = min(s.batch_size, n)
    if batch_size < 1 or s.epochs < 1:
        raise ValueError(f"pretrain_dino: need batch_size >= 1 and epochs >= 1 (n={n})")
    local_size = s.local_size
    if local_size is None:
        local_size = max(2 * PATCH_SIZE, round(image_size * 3 / 7 / PATCH_SIZE) * PATCH_SIZE)
    if local_size % PATCH_SIZE:
        raise ValueError(
            f"pretrain_dino: local_size {local_size} is not a multiple of {PATCH_SIZE}"
        )
    if s.centering not in ("sinkhorn_knopp", "centre"):
        raise ValueError(
            f"pretrain_dino: centering must be 'sinkhorn_knopp' or 'centre', got {s.centering!r}"
        )
    if s.koleo_weight < 0 or s.freeze_last_layer_epochs < 0 or s.warmup_teacher_temp_epochs < 0:
        raise ValueError(
            "pretrain_dino: koleo_weight, freeze_last_layer_epochs and warmup_teacher_temp_epochs "
            f"must be >= 0, got {s.koleo_weight}, {s.freeze_last_layer_epochs}, "
            f"{s.warmup_teacher_temp_epochs}"
        )
    return batch_size, local_size


def _dino_nets(
    s: DinoSettings, *, arch: str, image_size: int, dev: torch.device
) -> tuple[_Net, _Net]:
    """(student, teacher) on `dev`: the student's weights drawn under torch's RNG forked and
    seeded with `seed`, the teacher its copy with no gradients."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(s.seed)
        backbone = build_vit(arch, img_size=image_size)
        head = DINOHead(backbone.embed_dim, s.out_dim, s.hidden_dim, s.bottleneck_dim)
        student = _Net(backbone, head)
    teacher = copy.deepcopy(student)
    for p in teacher.parameters():
        p.requires_grad_(False)
    student.to(dev)
    teacher.to(dev)
    return student, teacher


def _dino_optimizer(student: _Net, s: DinoSettings) -> AdamW:
    """AdamW over the student: weight decay on its weight matrices, none on biases, norms,
    LayerScale, tokens and the position embedding."""
    decay = [p for nm, p in student.named_parameters() if p.ndim > 1 and "token" not in nm]
    no_decay = [p for nm, p in student.named_parameters() if not (p.ndim > 1 and "token" not in nm)]
    # pos_embed has ndim 3: keep it out of weight decay too (DINO does not decay it)
    decay = [p for p in decay if p is not student.backbone.pos_embed]
    no_decay.append(student.backbone.pos_embed)
    return AdamW(
        [
            {"params": decay, "weight_decay": s.weight_decay},
            {"params": no_decay, "weight_decay": 0.0},
        ],
        lr=s.lr,
    )


def _dino_schedules(s: DinoSettings, *, n: int, batch_size: int) -> DinoSchedules:
    """The per-step schedules of a run on `n` frames: lr warm-up then cosine
    (`warmup_cosine_lr`), teacher momentum cosine to 1, teacher temperature linear over its
    warm-up then constant, and the steps of the frozen last layer."""
    steps_per_epoch = max(1, n // batch_size)
    total = steps_per_epoch * s.epochs
    warm = min(total, s.warmup_epochs * steps_per_epoch)
    t_warm = min(total, s.warmup_teacher_temp_epochs * steps_per_epoch)
    tt_start = s.teacher_temp if s.warmup_teacher_temp is None else s.warmup_teacher_temp
    return DinoSchedules(
        steps_per_epoch=steps_per_epoch,
        lr=warmup_cosine_lr(s.lr, warm, total),
        momentum=cosine_schedule(s.momentum_teacher, 1.0, total),
        teacher_temp=np.concatenate(
            [
                np.linspace(tt_start, s.teacher_temp, t_warm),
                np.full(total - t_warm, s.teacher_temp),
            ]
        ),
        frozen_steps=s.freeze_last_layer_epochs * steps_per_epoch,
    )


def pretrain_dino(
    images: np.ndarray,
    settings: DinoSettings,
    *,
    arch: str,
    image_size: int,
    progress: Callable[[str], None] | None = None,
    device: torch.device | str,
) -> PretrainResult:
    """Pretrain a backbone of `arch` on uint8 frames (N, H, W, 3) with DINO; see module doc.

    device: where student and teacher train (`tacgen_lib.runtime.device`). They are built, the
    frames resized and every crop drawn on the CPU, then moved (on the CPU no move); the
    backbone's state comes back on the CPU. On a GPU, an op without a deterministic kernel
    warns instead of stopping.

    settings: every term of the recipe (`DinoSettings`, from config ``features.pretrain``);
    the names below are its fields.

    Frames are resized once to image_size x image_size (features.to_unit_tensor); global crops
    are image_size, local crops `local_size` (default: the multiple of 14 nearest 3/7 of
    image_size, at least 28). Optimiser: AdamW (no decay on biases, norms, LayerScale and
    tokens), lr linear warm-up over `warmup_epochs` then cosine to lr/100, gradient-norm
    clipping at `clip_grad`; teacher EMA momentum cosine from `momentum_teacher` to 1.
    Teacher targets: centering="sinkhorn_knopp" (default; `sinkhorn_iterations` as DINOv2) or
    "centre" (DINO v1 running centre with `center_momentum`; the centre starts at the first
    teacher batch's mean, as from zero the first steps sharpen the component all frames share
    into one target). Teacher temperature: linear from `warmup_teacher_temp` (default: no
    warm-up) to `teacher_temp` over `warmup_teacher_temp_epochs`. `koleo_weight` scales the
    KoLeo term (0 turns it off); the head's last layer gets no update for the first
    `freeze_last_layer_epochs`. With centering="centre", koleo_weight=0 and
    freeze_last_layer_epochs=0 the run is the previous recipe, bit for bit.
    The last incomplete batch of each epoch is dropped, so every step has the same batch size
    (the order is reshuffled every epoch, so all frames are seen); batch_size is capped at N.

    CPU threads: set torch.set_num_threads(...) to the cores the job owns. On an oversubscribed
    machine 2 OpenMP threads run several times slower than 1 (spin-waits). Bit-identical
    reruns need the same thread count.
    """
    s = settings
    batch_size, local_size = _checked_sizes(images, s, image_size)
    say = progress or (lambda _msg: None)

    dev = torch.device(device)
    with deterministic_algorithms(warn_only=dev.type != "cpu"):
        student, teacher = _dino_nets(s, arch=arch, image_size=image_size, dev=dev)
        # resized once, in chunks, so large raw frames never sit in memory as float32
        n = images.shape[0]
        data = torch.cat(
            [to_unit_tensor(images[i : i + 256], image_size) for i in range(0, n, 256)]
        )
        order_rng = np.random.default_rng(s.seed)
        gen = torch.Generator().manual_seed(s.seed)
        run = DinoRun(
            settings=s,
            student=student,
            teacher=teacher,
            opt=_dino_optimizer(student, s),
            sched=_dino_schedules(s, n=n, batch_size=batch_size),
            dev=dev,
            batch_size=batch_size,
            image_size=image_size,
            local_size=local_size,
        )
        curve: list[dict[str, float]] = []
        for epoch in range(s.epochs):
            row = dino_epoch(run, data, order_rng, gen, epoch)
            curve.append(row)
            say(
                f"dino epoch {epoch + 1}/{s.epochs}: loss {row['loss']:.4f} "
                f"H(teacher) {row['teacher_entropy']:.3f} "
                f"H(batch-mean teacher) {row['teacher_batch_entropy']:.3f} "
                f"KL {row['kl']:.4f} KoLeo {row['koleo']:.3f} "
                f"cos(teacher CLS) {row['teacher_cls_cosine']:.3f} ({row['seconds']:.1f}s)"
            )

    state = {k: v.detach().cpu().clone() for k, v in teacher.backbone.state_dict().items()}
    return PretrainResult(arch=arch, image_size=image_size, backbone_state=state, curve=curve)
