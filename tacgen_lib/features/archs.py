"""The ViT architectures by name (`ARCHS`) and the patch size: plain numbers, no torch.

The backbone (`tacgen_lib.features.vit`, which imports torch) builds its networks from these;
the run-time estimate (`tacgen_lib.runtime.units`: FLOPs of a forward) and the Snakefile's cost
plans (a knob's embed width) read them without importing torch (~1 s).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ARCHS", "PATCH_SIZE", "ViTConfig"]

PATCH_SIZE = 14


@dataclass(frozen=True)
class ViTConfig:
    """Width, depth and heads of one named architecture (mlp_ratio 4, LayerScale 1.0 as DINOv2)."""

    embed_dim: int
    depth: int
    num_heads: int
    mlp_ratio: float = 4.0


# vit_small / vit_base are the DINOv2 ViT-S/14 and ViT-B/14 shapes. vit_tiny is ours, sized for
# in-workflow DINO pretraining on 2 CPU cores (DeiT-Ti width, half the depth).
ARCHS: dict[str, ViTConfig] = {
    "vit_tiny": ViTConfig(embed_dim=192, depth=6, num_heads=3),
    "vit_small": ViTConfig(embed_dim=384, depth=12, num_heads=6),
    "vit_base": ViTConfig(embed_dim=768, depth=12, num_heads=12),
}
