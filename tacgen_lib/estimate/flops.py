"""The arithmetic of the workflow's models, for the run-time estimate: FLOPs of one frame
through a backbone (a ViT, a ResNet), of one row through the latent generator's MLP, of one
frame through a pixel generator, read from the merged config; and their seconds at the
calibration CPU's effective GEMM rate (`flop_seconds`). `tacgen_lib.estimate.units` charges a
rule's FLOPs this way, so a model a hundred times larger than any calibrated one costs a
hundred times its arithmetic, not a hundred times its calibrated overheads.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from tacgen_lib.features.archs import ARCHS, RESNET_ARCHS, arch_family
from tacgen_lib.features.settings import backbone_image_size

__all__ = [
    "GFLOPS_PER_THREAD",
    "MAE_FORWARDS",
    "DINO_FORWARDS",
    "SIMCLR_FORWARDS",
    "flop_seconds",
    "vit_flops",
    "resnet_flops",
    "arch_flops",
    "backbone_flops",
    "spec_flops",
    "generator_mlp_flops",
    "pixel_frame",
    "pixel_forward_flops",
]

Config = Mapping[str, Any]


#: Effective dense float32 rate per thread of the calibration's CPU (2-core AMD EPYC, AVX-512):
#: about half its one-thread GEMM peak (benchmarks/machine.py prints a machine's), as training
#: reaches only part of the roofline, less on small layers (README, Speed). Scale with
#: --speed-factor on another CPU class.
GFLOPS_PER_THREAD = 50.0


def vit_flops(arch: str, image_size: int) -> float:
    """FLOPs of one frame through a ViT forward: 2 × depth × tokens × (12 width² + 2 tokens ×
    width) (projections and MLP, attention)."""
    width, depth = ARCHS[arch].embed_dim, ARCHS[arch].depth
    tokens = (int(image_size) // ARCHS[arch].patch_size) ** 2 + 1
    return 2.0 * depth * tokens * (12 * width**2 + 2 * tokens * width)


def resnet_flops(arch: str, image_size: int) -> float:
    """FLOPs of one frame through a ResNet forward: 2 × output pixels × k² × C_in × C_out per
    convolution (the 7×7 stem at 1/2, two 3×3 per block at each stage's resolution from 1/4
    to 1/32, the first block's stride and 1×1 projection included)."""
    cfg = RESNET_ARCHS[arch]
    side = int(image_size) / 2.0
    flops = 2.0 * side * side * 49 * 3 * cfg.widths[0]
    side /= 2.0  # max-pool
    c_in = cfg.widths[0]
    for stage, (blocks, width) in enumerate(zip(cfg.blocks, cfg.widths, strict=True)):
        if stage:
            side /= 2.0
        for b in range(blocks):
            flops += 2.0 * side * side * 9 * (c_in * width + width * width)
            if b == 0 and c_in != width:
                flops += 2.0 * side * side * c_in * width
            c_in = width
    return flops


def arch_flops(arch: str, image_size: int) -> float:
    """Forward FLOPs of one frame through a named backbone of either family."""
    if arch_family(arch) == "resnet":
        return resnet_flops(arch, image_size)
    return vit_flops(arch, image_size)


def spec_flops(c: Config, spec: Mapping[str, Any]) -> float:
    """`arch_flops` of a backbone declaration at the input size it reads
    (`features.settings.backbone_image_size`: its own, else features.image_size)."""
    return arch_flops(spec["arch"], backbone_image_size(c["features"], spec))


def backbone_flops(c: Config, modality: str) -> float:
    """`spec_flops` of a modality's backbone (features.backbones)."""
    return spec_flops(c, c["features"]["backbones"][modality])


#: MAE pretraining per frame and epoch, in encoder forwards: the encoder sees a quarter of the
#: patches, forward + backward (3 forwards), plus the light decoder (about one more)
MAE_FORWARDS = 1.75


#: SimCLR per frame and epoch, in backbone forwards: 2 crops, forward + backward (3 forwards).
SIMCLR_FORWARDS = 6


#: DINO self-distillation per frame and epoch, in ViT forwards: 2 global crops through the
#: student (forward + backward = 3 forwards) and the teacher (1), local crops left out.
DINO_FORWARDS = 8


def generator_mlp_flops(c: Config) -> float:
    """FLOPs of one row through the residual MLP forward (2 hidden² layers per block, plus the
    input and output layers of ~3 × 768-d features)."""
    g = c["generate"]
    h = int(g["hidden"])
    return 2.0 * (int(g["blocks"]) * 2 * h * h + 3 * 768 * h)


def pixel_frame(c: Config) -> float:
    """Pixels of the pixel generators' frames (`pixel.size`)."""
    h, w = c["pixel"]["size"]
    return float(h) * float(w)


def pixel_forward_flops(c: Config, generator: str) -> float:
    """Approximate FLOPs of one frame through a pixel generator's forward: per U-Net level of
    the frame's 1/4**level pixels, its convolutions (Pix2Pix: a 4 x 4 down and up convolution
    per width; the DDPM's U-Net: two 3 x 3 convolutions per ResNet block, layers_per_block
    down and one more up, a skip concatenation doubling the up blocks' inputs), multiply-add
    = 2. An estimate for pricing bigger models, not a count of every operation."""
    px = pixel_frame(c)
    if generator == "pix2pix":
        ch = [3, *(int(x) for x in c["pixel"]["pix2pix"]["channels"])]
        enc = sum(px / 4 ** (i + 1) * 16 * ch[i] * ch[i + 1] for i in range(len(ch) - 1))
        disc = [6, *(int(x) for x in c["pixel"]["pix2pix"]["disc_channels"])]
        d = sum(px / 4 ** (i + 1) * 16 * disc[i] * disc[i + 1] for i in range(len(disc) - 1))
        return 2.0 * (3 * enc + d)  # decoder ~ 2 x encoder (skip inputs), + the discriminator
    d = c["pixel"]["ddpm"]
    ch, lpb = [int(x) for x in d["channels"]], int(d["layers_per_block"])
    total = 0.0
    for level, width in enumerate(ch):
        per_block = 2 * 9 * width * width * px / 4**level
        total += per_block * (lpb + (lpb + 1) * 1.5)  # down blocks; up blocks with skips
    return 2.0 * total


def flop_seconds(flops: float, threads: int) -> float:
    """Seconds of `flops` at the effective GEMM rate of `threads` threads."""
    return flops / (GFLOPS_PER_THREAD * 1e9 * max(1, threads))
