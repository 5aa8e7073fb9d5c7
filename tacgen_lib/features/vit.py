"""The frozen-feature backbone: a DINOv2-architecture Vision Transformer.

This module owns the ViT (patch 14, CLS token, optional register tokens, learned position
embeddings interpolated to the input grid, pre-norm blocks with LayerScale, final norm, mask
token) and its construction by architecture name (`build_vit`, from the registry
`tacgen_lib.features.archs.ARCHS`); reading and writing its weights is
`tacgen_lib.features.vit_checkpoint`. It is a compact re-implementation (timm would
pull torchvision, which cannot be imported here) whose parameter names are those of the official
DINOv2 checkpoints, so `dinov2_vits14_pretrain.pth` / `dinov2_vitb14_pretrain.pth` (and the
`_reg4_` variants) load without renaming:

    cls_token [1, 1, D]          pos_embed [1, 1 + G*G, D]     mask_token [1, D]
    register_tokens [1, R, D]    (register variants only)
    patch_embed.proj.{weight,bias}
    blocks.{i}.norm1 / attn.qkv / attn.proj / ls1.gamma / norm2 / mlp.fc1 / mlp.fc2 / ls2.gamma
    norm.{weight,bias}

Names were checked against facebookresearch/dinov2 (dinov2/models/vision_transformer.py and
dinov2/layers/); the code here is our own. Attention is exact softmax attention computed with
plain matmuls (no fused kernel), so outputs are deterministic on CPU.

`forward_features` returns the DINOv2 dict (`x_norm_clstoken`, `x_norm_regtokens`,
`x_norm_patchtokens`, `x_prenorm`, `masks`); `forward` returns the normalised CLS token.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from tacgen_lib.features.archs import ARCHS, PATCH_SIZE, ViTConfig

__all__ = [
    "ARCHS",
    "PATCH_SIZE",
    "ViTConfig",
    "DinoVisionTransformer",
    "build_vit",
    "random_backbone",
    "interpolate_pos_embed",
]


class PatchEmbed(nn.Module):
    """Non-overlapping patch_size x patch_size patches -> D-dim tokens (a strided conv `proj`)."""

    def __init__(self, patch_size: int, in_chans: int, embed_dim: int) -> None:
        super().__init__()
        self.patch_size = patch_size
        self.proj = nn.Conv2d(in_chans, embed_dim, kernel_size=patch_size, stride=patch_size)

    def forward(self, x: Tensor) -> Tensor:
        _, _, h, w = x.shape
        p = self.patch_size
        if h % p or w % p:
            raise ValueError(
                f"PatchEmbed: image {h}x{w} is not a multiple of the patch size {p}; "
                f"resize to a multiple of {p} (e.g. {max(p, h // p * p)}x{max(p, w // p * p)})"
            )
        return self.proj(x).flatten(2).transpose(1, 2)  # (B, gh*gw, D)


class Attention(nn.Module):
    """Multi-head self-attention with a fused `qkv` projection and an output `proj`."""

    def __init__(self, dim: int, num_heads: int) -> None:
        super().__init__()
        if dim % num_heads:
            raise ValueError(f"Attention: dim {dim} is not divisible by num_heads {num_heads}")
        self.num_heads = num_heads
        self.scale = (dim // num_heads) ** -0.5
        self.qkv = nn.Linear(dim, dim * 3, bias=True)
        self.proj = nn.Linear(dim, dim, bias=True)

    def forward(self, x: Tensor) -> Tensor:
        b, n, d = x.shape
        qkv = self.qkv(x).reshape(b, n, 3, self.num_heads, d // self.num_heads)
        q, k, v = qkv.permute(2, 0, 3, 1, 4).unbind(0)  # each (B, heads, N, head_dim)
        attn = (q * self.scale) @ k.transpose(-2, -1)
        attn = attn.softmax(dim=-1)
        out = (attn @ v).transpose(1, 2).reshape(b, n, d)
        return self.proj(out)


class Mlp(nn.Module):
    """fc1 -> GELU -> fc2."""

    def __init__(self, dim: int, hidden: int) -> None:
        super().__init__()
        self.fc1 = nn.Linear(dim, hidden)
        self.act = nn.GELU()
        self.fc2 = nn.Linear(hidden, dim)

    def forward(self, x: Tensor) -> Tensor:
        return self.fc2(self.act(self.fc1(x)))


class LayerScale(nn.Module):
    """Per-channel residual-branch scale `gamma` (DINOv2 init_values=1.0)."""

    def __init__(self, dim: int, init_values: float = 1.0) -> None:
        super().__init__()
        self.gamma = nn.Parameter(torch.full((dim,), float(init_values)))

    def forward(self, x: Tensor) -> Tensor:
        return x * self.gamma


class Block(nn.Module):
    """Pre-norm transformer block: x + ls1(attn(norm1 x)), then x + ls2(mlp(norm2 x))."""

    def __init__(self, dim: int, num_heads: int, mlp_ratio: float) -> None:
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = Attention(dim, num_heads)
        self.ls1 = LayerScale(dim)
        self.norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = Mlp(dim, int(dim * mlp_ratio))
        self.ls2 = LayerScale(dim)

    def forward(self, x: Tensor) -> Tensor:
        x = x + self.ls1(self.attn(self.norm1(x)))
        return x + self.ls2(self.mlp(self.norm2(x)))


def interpolate_pos_embed(
    patch_pos_embed: Tensor,
    grid: tuple[int, int],
    *,
    offset: float,
    antialias: bool,
) -> Tensor:
    """Bicubic resize of a square grid of position embeddings to `grid` = (rows, cols), as
    DINOv2's `interpolate_pos_encoding` does it.

    patch_pos_embed: (1, M*M, D) embeddings of the patch tokens (no CLS). Returns (1, rows*cols, D)
    float32. With `offset` > 0 the resize is driven by the scale factor (rows + offset) / M, the
    DINOv2 "interpolate_offset" kludge kept for output parity with the official non-register
    models (offset 0.1); with offset 0 the output size is given directly (register models, with
    `antialias` on). Both settings are the caller's: a checkpoint's features equal its own
    code's only with that code's pair (`DinoVisionTransformer.interpolate_offset` /
    `interpolate_antialias`; MAE: 0 and off).
    """
    _, n, dim = patch_pos_embed.shape
    m = math.isqrt(n)
    if m * m != n:
        raise ValueError(f"interpolate_pos_embed: {n} patch positions do not form a square grid")
    rows, cols = grid
    if (rows, cols) == (m, m):
        return patch_pos_embed.float()
    src = patch_pos_embed.float().reshape(1, m, m, dim).permute(0, 3, 1, 2)
    if offset:
        out = F.interpolate(
            src,
            scale_factor=((rows + offset) / m, (cols + offset) / m),
            mode="bicubic",
            antialias=antialias,
        )
    else:
        out = F.interpolate(src, size=(rows, cols), mode="bicubic", antialias=antialias)
    if tuple(out.shape[-2:]) != (rows, cols):
        raise RuntimeError(
            f"interpolate_pos_embed: got grid {tuple(out.shape[-2:])}, expected {(rows, cols)}"
        )
    return out.permute(0, 2, 3, 1).reshape(1, rows * cols, dim)


class DinoVisionTransformer(nn.Module):
    """DINOv2-architecture ViT; see the module docstring for the parameter names.

    img_size fixes the size of the learned `pos_embed` grid (img_size // patch_size per side,
    518 -> 37x37 for the official checkpoints); any input whose sides are multiples of the patch
    size is accepted, its position embeddings being bicubically interpolated to the input grid.
    """

    def __init__(
        self,
        *,
        img_size: int = 518,
        patch_size: int = PATCH_SIZE,
        embed_dim: int = 384,
        depth: int = 12,
        num_heads: int = 6,
        mlp_ratio: float = 4.0,
        num_register_tokens: int = 0,
        interpolate_offset: float = 0.1,
        interpolate_antialias: bool = False,
    ) -> None:
        super().__init__()
        if img_size % patch_size:
            raise ValueError(f"img_size {img_size} is not a multiple of patch_size {patch_size}")
        if num_register_tokens < 0:
            raise ValueError(f"num_register_tokens must be >= 0, got {num_register_tokens}")
        self.embed_dim = self.num_features = embed_dim
        self.patch_size = patch_size
        self.num_heads = num_heads
        self.num_register_tokens = num_register_tokens
        self.interpolate_offset = interpolate_offset
        self.interpolate_antialias = interpolate_antialias
        self.grid_size = img_size // patch_size

        self.patch_embed = PatchEmbed(patch_size, 3, embed_dim)
        self.cls_token = nn.Parameter(torch.zeros(1, 1, embed_dim))
        self.pos_embed = nn.Parameter(torch.zeros(1, 1 + self.grid_size**2, embed_dim))
        self.register_tokens = (
            nn.Parameter(torch.zeros(1, num_register_tokens, embed_dim))
            if num_register_tokens
            else None
        )
        self.blocks = nn.ModuleList(Block(embed_dim, num_heads, mlp_ratio) for _ in range(depth))
        self.norm = nn.LayerNorm(embed_dim, eps=1e-6)
        self.mask_token = nn.Parameter(torch.zeros(1, embed_dim))
        self.init_weights()

    def init_weights(self) -> None:
        """timm/DINOv2 init: trunc-normal(0.02) linears and pos_embed, tiny CLS/registers."""
        nn.init.trunc_normal_(self.pos_embed, std=0.02)
        nn.init.normal_(self.cls_token, std=1e-6)
        if self.register_tokens is not None:
            nn.init.normal_(self.register_tokens, std=1e-6)
        for module in self.modules():
            if isinstance(module, nn.Linear):
                nn.init.trunc_normal_(module.weight, std=0.02)
                nn.init.zeros_(module.bias)

    def interpolate_pos_encoding(self, rows: int, cols: int) -> Tensor:
        """Position embeddings (1, 1 + rows*cols, D) for a rows x cols patch grid."""
        cls_pos = self.pos_embed[:, :1].float()
        patch_pos = interpolate_pos_embed(
            self.pos_embed[:, 1:],
            (rows, cols),
            offset=self.interpolate_offset,
            antialias=self.interpolate_antialias,
        )
        return torch.cat((cls_pos, patch_pos), dim=1).to(self.pos_embed.dtype)

    def prepare_tokens_with_masks(self, x: Tensor, masks: Tensor | None = None) -> Tensor:
        """Patch tokens (+mask_token where masked), CLS, position embeddings, then registers."""
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"expected images (B, 3, H, W), got shape {tuple(x.shape)}")
        rows, cols = x.shape[2] // self.patch_size, x.shape[3] // self.patch_size
        tokens = self.patch_embed(x)
        if masks is not None:
            tokens = torch.where(masks.unsqueeze(-1), self.mask_token.to(tokens.dtype), tokens)
        tokens = torch.cat((self.cls_token.expand(tokens.shape[0], -1, -1), tokens), dim=1)
        tokens = tokens + self.interpolate_pos_encoding(rows, cols)
        if self.register_tokens is not None:
            regs = self.register_tokens.expand(tokens.shape[0], -1, -1)
            tokens = torch.cat((tokens[:, :1], regs, tokens[:, 1:]), dim=1)
        return tokens

    def forward_features(self, x: Tensor, masks: Tensor | None = None) -> dict[str, Tensor | None]:
        """DINOv2 output dict: normalised CLS, register and patch tokens, and pre-norm tokens."""
        tokens = self.prepare_tokens_with_masks(x, masks)
        for blk in self.blocks:
            tokens = blk(tokens)
        x_norm = self.norm(tokens)
        r = self.num_register_tokens
        return {
            "x_norm_clstoken": x_norm[:, 0],
            "x_norm_regtokens": x_norm[:, 1 : r + 1],
            "x_norm_patchtokens": x_norm[:, r + 1 :],
            "x_prenorm": tokens,
            "masks": masks,
        }

    def forward(self, x: Tensor) -> Tensor:
        """The normalised CLS token (B, D)."""
        out = self.forward_features(x)["x_norm_clstoken"]
        assert isinstance(out, Tensor)
        return out


def build_vit(
    arch: str, *, img_size: int = 518, num_register_tokens: int = 0
) -> DinoVisionTransformer:
    """A freshly initialised ViT of a named architecture (see ARCHS).

    Register variants use DINOv2's reg4 interpolation settings (no offset, antialias on);
    plain variants keep the official offset 0.1.
    """
    if arch not in ARCHS:
        raise ValueError(f"unknown ViT arch {arch!r}; valid: {sorted(ARCHS)}")
    cfg = ARCHS[arch]
    return DinoVisionTransformer(
        img_size=img_size,
        patch_size=cfg.patch_size,
        embed_dim=cfg.embed_dim,
        depth=cfg.depth,
        num_heads=cfg.num_heads,
        mlp_ratio=cfg.mlp_ratio,
        num_register_tokens=num_register_tokens,
        interpolate_offset=0.0 if num_register_tokens else 0.1,
        interpolate_antialias=bool(num_register_tokens),
    )


def random_backbone(arch: str, image_size: int, seed: int) -> DinoVisionTransformer:
    """The seeded random-init ViT of `arch` in eval mode: the baseline a pretrained backbone
    must beat, and the frozen backbone itself when `features.pretrain.epochs` is 0. Drawn under
    a forked RNG, so the caller's torch RNG is untouched; DINO pretraining starts from the same
    weights (`dino.pretrain_dino` builds the backbone first after seeding with `seed`)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return build_vit(arch, img_size=image_size).eval()
