"""Making and reading a frozen backbone of any family: the one entry point of the rules that
make one (`pretrain_backbone`, `family_backbone`, which also extracts) and that extract
(`extract_*_features`).

`make_backbone` turns a `families.BackboneSpec` into weights: an official checkpoint (DINOv2 or
MAE format for a ViT, torchvision format for a ResNet), or in-workflow pretraining (DINO,
`dino.pretrain_dino`, and MAE, `mae.pretrain_mae`, for a ViT; SimCLR, `simclr.pretrain_simclr`,
for a ResNet), or the seeded random init (a ResNet, or a
DINO ViT at 0 epochs). `read_backbone` builds whichever network a saved state dict describes.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from tacgen_lib.features.archs import arch_family
from tacgen_lib.features.dino import pretrain_dino
from tacgen_lib.features.families import BackboneSpec
from tacgen_lib.features.mae import load_mae_checkpoint, pretrain_mae
from tacgen_lib.features.resnet import random_resnet, resnet_from_state_dict
from tacgen_lib.features.settings import DinoSettings, MaeSettings, SimclrSettings
from tacgen_lib.features.simclr import pretrain_simclr
from tacgen_lib.features.vit import build_vit, random_backbone
from tacgen_lib.features.vit_checkpoint import (
    load_backbone,
    load_pretrained,
    load_tensors,
    unwrap_state_dict,
)

__all__ = ["make_backbone", "random_init", "read_backbone"]


def random_init(arch: str, image_size: int, seed: int) -> nn.Module:
    """The seeded random-init backbone of `arch` in eval mode, a ViT (`vit.random_backbone`)
    or a ResNet (`resnet.random_resnet`): the frozen backbone of objective random, and the
    baseline a pretrained one must beat (rule pretrained_vs_random)."""
    if arch_family(arch) == "resnet":
        return random_resnet(arch, seed=seed)
    return random_backbone(arch, image_size, seed=seed)


def make_backbone(
    spec: BackboneSpec,
    *,
    image_size: int,
    dino: DinoSettings,
    mae: MaeSettings,
    frames: Callable[[], np.ndarray],
    simclr: SimclrSettings | None = None,
    progress: Callable[[str], None] | None = None,
    device: torch.device | str,
) -> tuple[nn.Module, list[dict[str, float]], str]:
    """The frozen backbone of `spec` (eval mode), its pretraining curve (one dict per epoch;
    empty without pretraining) and a sentence saying how it was made.

    `frames()` returns the uint8 train frames (N, H, W, 3) to pretrain on; it is called only
    when pretraining runs. The random init's seed is `dino.seed` (as today's random ViT).
    `simclr`: the SimCLR settings of a backbone whose objective is simclr (None: the schema's
    defaults). `device`: where pretraining runs (the backbone returned is on the CPU).
    """
    say = progress or (lambda _m: None)
    if spec.checkpoint:
        if spec.network == "resnet":
            sd = unwrap_state_dict(load_tensors(spec.checkpoint), where=spec.checkpoint)
            model: nn.Module = resnet_from_state_dict(sd, where=spec.checkpoint)
        else:
            vit = build_vit(
                spec.arch, img_size=image_size, num_register_tokens=spec.num_register_tokens
            )
            load = load_mae_checkpoint if spec.objective == "mae" else load_pretrained
            model = load(vit, spec.checkpoint)
        return model.eval(), [], f"loaded official checkpoint {spec.checkpoint}"
    if not spec.pretrains(dino.epochs):  # the checkpoint was read above
        model = random_init(spec.arch, image_size, seed=dino.seed)
        return model, [], f"random-init {spec.arch} (seed {dino.seed}), no pretraining"
    if spec.objective == "simclr":
        images = frames()
        say(f"SimCLR pretraining of {spec.arch} on {len(images)} train frames")
        simclr_result = pretrain_simclr(
            images,
            simclr or SimclrSettings(),
            arch=spec.arch,
            image_size=image_size,
            pool=spec.pool or "cls",  # the projection reads what the features will read
            progress=say,
            device=device,
        )
        # wall-clock seconds stay in the log and the benchmark file: the edge is reproducible
        curve = [{k: v for k, v in r.items() if k != "seconds"} for r in simclr_result.curve]
        return simclr_result.backbone(), curve, f"SimCLR-pretrained {spec.arch}"
    if spec.objective == "mae":
        images = frames()
        say(f"MAE pretraining of {spec.arch} on {len(images)} train frames")
        mae_result = pretrain_mae(
            images, mae, arch=spec.arch, image_size=image_size, progress=say, device=device
        )
        return mae_result.backbone(), mae_result.curve, f"MAE-pretrained {spec.arch}"
    images = frames()
    say(f"DINO pretraining of {spec.arch} on {len(images)} train frames")
    result = pretrain_dino(
        images, dino, arch=spec.arch, image_size=image_size, progress=say, device=device
    )
    # wall-clock seconds stay in the log and the benchmark file: the edge must be reproducible
    curve = [{k: v for k, v in row.items() if k != "seconds"} for row in result.curve]
    return result.backbone(), curve, f"DINO-pretrained {spec.arch}"


def read_backbone(path: str | Path) -> nn.Module:
    """The network a saved state dict describes, loaded and in eval mode: a ViT (it has a
    cls_token, `vit_checkpoint.load_backbone`) or a ResNet (torchvision names); anything else is refused
    naming the file."""
    sd = unwrap_state_dict(load_tensors(path), where=str(path))
    if "cls_token" in sd:
        return load_backbone(path).eval()
    if "conv1.weight" in sd:
        return resnet_from_state_dict(sd, where=path)
    raise ValueError(
        f"{path}: neither a ViT (cls_token) nor a ResNet (conv1.weight) state dict; "
        f"first keys: {sorted(sd)[:5]}"
    )
