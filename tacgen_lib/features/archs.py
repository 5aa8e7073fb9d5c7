"""The backbone architectures by name and the patch size: plain numbers, no torch.

Two network families: the DINOv2-architecture ViTs (`ARCHS`, `tacgen_lib.features.vit`) and
torchvision-shaped ResNets (`RESNET_ARCHS`, `tacgen_lib.features.resnet`). `arch_family` tells
which family a name belongs to and `feature_dim` the width of its frozen feature.

The backbone (`tacgen_lib.features.vit`, which imports torch) builds its networks from these;
the run-time estimate (`tacgen_lib.estimate.units`: FLOPs of a forward) and the Snakefile's cost
plans (a knob's embed width) read them without importing torch (~1 s).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ARCHS",
    "PATCH_SIZE",
    "RESNET_ARCHS",
    "ResNetConfig",
    "ViTConfig",
    "arch_family",
    "feature_dim",
]

PATCH_SIZE = 14


@dataclass(frozen=True)
class ViTConfig:
    """Width, depth, heads and patch of one named architecture (mlp_ratio 4, LayerScale 1.0 as
    DINOv2; patch 14 as DINOv2, 16 as MAE)."""

    embed_dim: int
    depth: int
    num_heads: int
    mlp_ratio: float = 4.0
    patch_size: int = PATCH_SIZE


# vit_small / vit_base are the DINOv2 ViT-S/14 and ViT-B/14 shapes. vit_tiny is ours, sized for
# in-workflow DINO pretraining on 2 CPU cores (DeiT-Ti width, half the depth).
ARCHS: dict[str, ViTConfig] = {
    "vit_tiny": ViTConfig(embed_dim=192, depth=6, num_heads=3),
    "vit_small": ViTConfig(embed_dim=384, depth=12, num_heads=6),
    "vit_base": ViTConfig(embed_dim=768, depth=12, num_heads=12),
    # the ViT-B/16 of the official MAE releases (mae_pretrain_vit_base.pth): a 16-pixel patch
    "vit_base_p16": ViTConfig(embed_dim=768, depth=12, num_heads=12, patch_size=16),
}


@dataclass(frozen=True)
class ResNetConfig:
    """BasicBlocks per stage and each stage's width (the stem has the first stage's width)."""

    blocks: tuple[int, int, int, int]
    widths: tuple[int, int, int, int]


# resnet18 is torchvision's (its official checkpoint loads); resnet_tiny is ours, one block per
# stage at a quarter of the width, sized for frozen random or briefly trained features on CPU.
RESNET_ARCHS: dict[str, ResNetConfig] = {
    "resnet18": ResNetConfig(blocks=(2, 2, 2, 2), widths=(64, 128, 256, 512)),
    "resnet_tiny": ResNetConfig(blocks=(1, 1, 1, 1), widths=(16, 32, 64, 128)),
}


def arch_family(arch: str) -> str:
    """ "vit" or "resnet": the network family of a named architecture (ValueError if unknown)."""
    if arch in ARCHS:
        return "vit"
    if arch in RESNET_ARCHS:
        return "resnet"
    raise ValueError(
        f"unknown backbone arch {arch!r}; valid: {sorted(ARCHS) + sorted(RESNET_ARCHS)}"
    )


def feature_dim(arch: str) -> int:
    """Width of the frozen feature of `arch` (a ViT's embed_dim, a ResNet's last stage)."""
    return ARCHS[arch].embed_dim if arch_family(arch) == "vit" else RESNET_ARCHS[arch].widths[-1]
