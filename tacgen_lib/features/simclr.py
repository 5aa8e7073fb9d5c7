"""Contrastive pretraining of a convolutional backbone (objective ``simclr``): two augmented
views of every frame pulled together, the other frames of the batch pushed apart.

The recipe is SimCLR's (Chen et al. 2020, "A Simple Framework for Contrastive Learning of
Visual Representations"): a random resized crop with a horizontal flip per view
(`augment.random_resized_crop`, DINO's crop), an optional random greyscale per view, a
two-layer MLP projection behind the pooled feature, and the symmetric InfoNCE loss between the
two views' l2-normalised projections (`align.loss.info_nce`, the alignment's own loss; each
frame's negatives are the other frames' second views, as in MoCo v3's symmetric form). The
projection is dropped after training: the frozen feature is read from the backbone by
`extract.extract_features` (its pool: the last stage's average, or the stage statistics).

The projection reads the feature the workflow reads (`pool`): the last stage's average, or,
for the ``stages`` pool, the stage statistics (`resnet.ResNet.stage_statistics`: the early
stages' std over space beside the last stage's mean). Trained through the last stage's average
alone, the early stages' statistics are a by-product the loss never asks to separate frames;
trained through the statistics, every number a probe reads is one the contrastive loss shaped
(report page What vision sees; docs/features.md, The default vision side).

Why it exists beside DINO and MAE: a ViT with 14-pixel patches at the backbone's small input
reads colour but not the fine texture of an object (report page What vision sees), while a
convolutional network's small receptive fields see local texture by construction. The
augmentation has no colour jitter by default (`grey` 0), so colour, half of the natural
corpora's appearance class, is not made invariant; `grey` > 0 trades colour for texture.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn
from torch.optim import AdamW

from tacgen_lib.align.loss import info_nce
from tacgen_lib.features.archs import RESNET_ARCHS
from tacgen_lib.features.augment import random_resized_crop
from tacgen_lib.features.dino import deterministic_algorithms, warmup_cosine_lr
from tacgen_lib.features.extract import check_train_frames, imagenet_normalise, to_unit_tensor
from tacgen_lib.features.resnet import ResNet, build_resnet
from tacgen_lib.features.settings import SimclrSettings

__all__ = ["SimclrResult", "grey_views", "pretrain_simclr", "projection_head"]


@dataclass
class SimclrResult:
    """A finished run: the backbone's state (CPU), its arch and one curve row per epoch
    (epoch, loss: the mean InfoNCE of the epoch's steps, seconds: its wall time)."""

    arch: str
    backbone_state: dict[str, Tensor]
    curve: list[dict[str, float]] = field(default_factory=list)

    def backbone(self) -> ResNet:
        """A ResNet of `arch` carrying the pretrained weights, in eval mode."""
        model = build_resnet(self.arch)
        model.load_state_dict(self.backbone_state, strict=True)
        return model.eval()


def projection_head(in_dim: int, hidden_dim: int, out_dim: int) -> nn.Sequential:
    """SimCLR's projection g: Linear -> ReLU -> Linear (dropped after pretraining)."""
    return nn.Sequential(nn.Linear(in_dim, hidden_dim), nn.ReLU(), nn.Linear(hidden_dim, out_dim))


def grey_views(x: Tensor, p: float, gen: torch.Generator) -> Tensor:
    """Each image of (B, 3, H, W) in [0, 1] replaced, with probability `p`, by its channel mean
    repeated over the three channels; the draw comes from `gen` (one uniform per image, drawn
    even at p = 0, so the stream does not depend on p)."""
    u = torch.rand(x.shape[0], 1, 1, 1, generator=gen)
    grey = x.mean(dim=1, keepdim=True).expand_as(x)
    return torch.where(u < p, grey, x)


def pretrain_simclr(
    images: np.ndarray,
    settings: SimclrSettings,
    *,
    arch: str,
    image_size: int,
    pool: str,
    progress: Callable[[str], None] | None = None,
    device: torch.device | str,
) -> SimclrResult:
    """Pretrain a ResNet of `arch` on uint8 frames (N, H, W, 3) with SimCLR; see module doc.

    settings (config ``features.simclr``): `epochs`, `batch_size` (capped at N; the last
    incomplete batch of an epoch is dropped, the order reshuffled every epoch), `lr` (AdamW with
    `weight_decay`, linear warm-up over the first epoch, then cosine to lr/100), `tau` (the
    InfoNCE temperature), `crop_min` (the smallest crop, as a fraction of the frame's area),
    `grey` (the probability of a greyscale view), `hidden_dim` and `proj_dim` (the projection),
    `seed` (initialisation, order and augmentation). `pool`: the feature the projection reads,
    the one the backbone's features will be read by (``stages``: the stage statistics; any
    other pool of `extract.POOLS`: the last stage's average). Frames are resized once to
    image_size
    (`extract.to_unit_tensor`) and every view normalised as extraction normalises
    (`extract.imagenet_normalise`). Bit-identical reruns on one machine need the same torch
    thread count. Raises ValueError for an arch that is not a ResNet or frames that are not
    uint8 (N, H, W, 3).
    """
    if arch not in RESNET_ARCHS:
        raise ValueError(
            f"pretrain_simclr: {arch!r} is not a ResNet; valid: {sorted(RESNET_ARCHS)}"
        )
    check_train_frames(images, "pretrain_simclr")
    s = settings
    n = images.shape[0]
    batch_size = min(s.batch_size, n)
    if batch_size < 2:
        raise ValueError(f"pretrain_simclr: need at least 2 frames for negatives, got {n}")
    say = progress or (lambda _msg: None)
    dev = torch.device(device)
    with deterministic_algorithms(warn_only=dev.type != "cpu"):
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(s.seed)
            backbone = build_resnet(arch)
            stages = pool == "stages"
            read = backbone.stage_statistics if stages else backbone
            width = backbone.stage_statistics_dim if stages else backbone.num_features
            head = projection_head(width, s.hidden_dim, s.proj_dim)
        backbone.to(dev).train()
        head.to(dev).train()
        data = torch.cat(
            [to_unit_tensor(images[i : i + 256], image_size) for i in range(0, n, 256)]
        )
        order_rng = np.random.default_rng(s.seed)
        gen = torch.Generator().manual_seed(s.seed)
        opt = AdamW(
            [*backbone.parameters(), *head.parameters()], lr=s.lr, weight_decay=s.weight_decay
        )
        steps_per_epoch = n // batch_size
        total = steps_per_epoch * s.epochs
        warm = min(total, steps_per_epoch)
        lr_sched = warmup_cosine_lr(s.lr, warm, total)

        def view(batch: Tensor) -> Tensor:
            crops = random_resized_crop(batch, image_size, (s.crop_min, 1.0), gen)
            return imagenet_normalise(grey_views(crops, s.grey, gen)).to(dev)

        def project(x: Tensor) -> Tensor:
            return F.normalize(head(read(x)), dim=1)

        curve: list[dict[str, float]] = []
        step = 0
        for epoch in range(s.epochs):
            t0 = time.perf_counter()
            perm = order_rng.permutation(n)
            total_loss = 0.0
            for bi in range(steps_per_epoch):
                idx = torch.from_numpy(perm[bi * batch_size : (bi + 1) * batch_size])
                batch = data[idx]
                v1, v2 = view(batch), view(batch)
                for group in opt.param_groups:
                    group["lr"] = float(lr_sched[step])
                loss = info_nce(project(v1), project(v2), s.tau)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                total_loss += float(loss.detach())
                step += 1
            seconds = time.perf_counter() - t0
            row = {"epoch": epoch, "loss": total_loss / steps_per_epoch, "seconds": seconds}
            curve.append(row)
            say(
                f"SimCLR epoch {epoch + 1}/{s.epochs}: loss {row['loss']:.4f} "
                f"({seconds:.1f} s, {steps_per_epoch} steps of {batch_size})"
            )
    state = {k: v.detach().cpu().clone() for k, v in backbone.state_dict().items()}
    return SimclrResult(arch=arch, backbone_state=state, curve=curve)
