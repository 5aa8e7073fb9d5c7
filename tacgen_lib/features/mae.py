"""Masked-autoencoder pretraining of the ViT (He et al. 2022, "Masked Autoencoders Are Scalable
Vision Learners"), and the loader of official MAE encoder checkpoints.

This module owns the MAE objective: per frame, a random `mask_ratio` of the patches is hidden
(`random_masking`, MAE's per-sample argsort of uniform noise); the encoder (the project's
DINOv2-architecture ViT, `vit.DinoVisionTransformer`) sees the CLS token and the visible
patches only; a light decoder (`MaeDecoder`: a linear embedding, a learned mask token, learned
position embeddings, `decoder_depth` pre-norm blocks, a linear pixel head) predicts every
patch's pixels; the loss is the mean squared error on the hidden patches, against pixels
normalised per patch (`norm_pix_loss`, MAE's default). The decoder is discarded; the encoder is
the frozen backbone, saved in the same official key format as a DINO-pretrained one.

Differences from the paper's recipe, for frames of a few dozen pixels on 2 CPU cores: learned
(not fixed sin-cos) decoder position embeddings, no crop augmentation (a horizontal flip only),
and the encoder keeps the DINOv2 architecture's LayerScale (initialised to 1).

Official MAE releases (`mae_pretrain_vit_base.pth`: timm ViT names, patch 16) load with
`load_mae_checkpoint` into a ViT with a 16-pixel patch (`archs.ARCHS["vit_base_p16"]`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from tacgen_lib.features.dino import PretrainResult
from tacgen_lib.features.extract import check_train_frames, imagenet_normalise, to_unit_tensor
from tacgen_lib.features.settings import MaeSettings
from tacgen_lib.features.vit import Block, DinoVisionTransformer, build_vit
from tacgen_lib.features.vit_checkpoint import (
    fit_pos_embed,
    load_tensors,
    state_dict_mismatch,
    unwrap_state_dict,
)
from tacgen_lib.optim import AdamW

__all__ = [
    "MaeDecoder",
    "MaePretrainResult",
    "encode_visible",
    "load_mae_checkpoint",
    "mae_loss",
    "patchify",
    "pretrain_mae",
    "random_masking",
]


def patchify(x: Tensor, patch: int) -> Tensor:
    """(B, 3, H, W) -> (B, L, patch*patch*3), patches in row-major order, pixels (p, q, c)
    as MAE's `patchify`."""
    b, c, h, w = x.shape
    if h % patch or w % patch:
        raise ValueError(f"patchify: image {h}x{w} is not a multiple of the patch {patch}")
    x = x.reshape(b, c, h // patch, patch, w // patch, patch)
    return torch.einsum("bchpwq->bhwpqc", x).reshape(b, (h // patch) * (w // patch), -1)


def random_masking(
    batch: int, length: int, mask_ratio: float, generator: torch.Generator
) -> tuple[Tensor, Tensor, Tensor]:
    """MAE's per-sample random masking: (keep index (B, K), mask (B, L) with 1 = hidden,
    restore index (B, L)). K = round(L * (1 - mask_ratio)), at least 1."""
    if not 0.0 <= mask_ratio < 1.0:
        raise ValueError(f"random_masking: mask_ratio must be in [0, 1), got {mask_ratio}")
    keep = max(1, int(round(length * (1.0 - mask_ratio))))
    noise = torch.rand(batch, length, generator=generator)
    shuffle = torch.argsort(noise, dim=1)
    restore = torch.argsort(shuffle, dim=1)
    mask = torch.ones(batch, length)
    mask[:, :keep] = 0.0
    return shuffle[:, :keep], torch.gather(mask, 1, restore), restore


def encode_visible(vit: DinoVisionTransformer, x: Tensor, keep: Tensor) -> Tensor:
    """The encoder on the CLS token and the visible patches `keep` (B, K): normalised tokens
    (B, 1 + K, D), position embeddings added before the patches are dropped (as MAE)."""
    rows, cols = x.shape[2] // vit.patch_size, x.shape[3] // vit.patch_size
    pos = vit.interpolate_pos_encoding(rows, cols)
    tokens = vit.patch_embed(x) + pos[:, 1:]
    d = tokens.shape[-1]
    visible = torch.gather(tokens, 1, keep.unsqueeze(-1).expand(-1, -1, d))
    cls = (vit.cls_token + pos[:, :1]).expand(x.shape[0], -1, -1)
    seq = torch.cat((cls, visible), dim=1)
    for blk in vit.blocks:
        seq = blk(seq)
    return vit.norm(seq)


class MaeDecoder(nn.Module):
    """Encoder tokens -> per-patch pixels: embed, insert mask tokens, unshuffle, add position
    embeddings, `depth` blocks, norm, linear head (MAE's decoder, learned positions)."""

    def __init__(
        self, embed_dim: int, num_patches: int, dim: int, depth: int, heads: int, patch_dim: int
    ) -> None:
        super().__init__()
        self.embed = nn.Linear(embed_dim, dim)
        self.mask_token = nn.Parameter(torch.zeros(1, 1, dim))
        self.pos_embed = nn.Parameter(torch.zeros(1, 1 + num_patches, dim))
        self.blocks = nn.ModuleList(Block(dim, heads, 4.0) for _ in range(depth))
        self.norm = nn.LayerNorm(dim, eps=1e-6)
        self.pred = nn.Linear(dim, patch_dim)
        nn.init.normal_(self.mask_token, std=0.02)
        nn.init.trunc_normal_(self.pos_embed, std=0.02)
        for m in self.modules():
            if isinstance(m, nn.Linear):
                nn.init.xavier_uniform_(m.weight)
                nn.init.zeros_(m.bias)

    def forward(self, latent: Tensor, restore: Tensor) -> Tensor:
        x = self.embed(latent)
        b, k1, d = x.shape
        n = restore.shape[1]
        fill = self.mask_token.expand(b, n - (k1 - 1), -1)
        patches = torch.cat((x[:, 1:], fill), dim=1)
        patches = torch.gather(patches, 1, restore.unsqueeze(-1).expand(-1, -1, d))
        x = torch.cat((x[:, :1], patches), dim=1) + self.pos_embed
        for blk in self.blocks:
            x = blk(x)
        return self.pred(self.norm(x))[:, 1:]


def mae_loss(pred: Tensor, target: Tensor, mask: Tensor, *, norm_pix: bool) -> Tensor:
    """Mean squared error per patch, averaged over the hidden patches (mask 1) only; with
    `norm_pix`, each target patch is normalised by its own mean and variance (eps 1e-6)."""
    if norm_pix:
        mean = target.mean(dim=-1, keepdim=True)
        var = target.var(dim=-1, keepdim=True)
        target = (target - mean) / (var + 1.0e-6).sqrt()
    per_patch = ((pred - target) ** 2).mean(dim=-1)
    return (per_patch * mask).sum() / mask.sum()


class MaePretrainResult(PretrainResult):
    """Outcome of `pretrain_mae`: the encoder's weights in the official ViT key format
    (`backbone_state`; `backbone()` builds the ViT carrying them) and one dict per epoch
    (epoch, loss: the mean masked-patch MSE of its steps, lr)."""


def _mae_optimizer(vit: torch.nn.Module, decoder: torch.nn.Module, s: MaeSettings) -> AdamW:
    """AdamW over encoder and decoder as MAE sets it: betas 0.9, 0.95, weight decay on the
    weight matrices only (none on biases, norms, tokens and position embeddings)."""
    params = [
        *vit.named_parameters(),
        *(("decoder." + k, p) for k, p in decoder.named_parameters()),
    ]
    decay = [p for k, p in params if p.ndim > 1 and "token" not in k and "pos_embed" not in k]
    keep_ids = {id(p) for p in decay}
    no_decay = [p for _k, p in params if id(p) not in keep_ids]
    return AdamW(
        [
            {"params": decay, "weight_decay": s.weight_decay},
            {"params": no_decay, "weight_decay": 0.0},
        ],
        lr=s.lr,
        betas=(0.9, 0.95),
    )


def pretrain_mae(
    images: np.ndarray,
    settings: MaeSettings,
    *,
    arch: str,
    image_size: int,
    progress: Callable[[str], None] | None = None,
    device: torch.device | str,
) -> MaePretrainResult:
    """Pretrain a ViT of `arch` on uint8 frames (N, H, W, 3) with the MAE objective.

    Frames go through the features' input pipeline (`extract.to_unit_tensor`, ImageNet
    normalisation), so pretraining and extraction see the same inputs. AdamW (betas 0.9, 0.95
    as MAE; no decay on biases, norms and tokens), lr linear warm-up over `warmup_epochs`, then
    cosine to 0; the last incomplete batch of an epoch is dropped (batch capped at N). Seeded
    by `settings.seed` (weights, order, masks, flips); bit-identical reruns need the same
    thread count. `device`: where encoder and decoder train (`tacgen_lib.runtime.device`):
    built, and every flip and mask drawn, on the CPU, then moved (on the CPU no move); the
    encoder's state comes back on the CPU.
    """
    s = settings
    check_train_frames(images, "pretrain_mae")
    n = images.shape[0]
    if n < 1:
        raise ValueError("pretrain_mae: no frames to learn from")
    say = progress or (lambda _msg: None)
    batch = min(s.batch_size, n)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(s.seed)
        vit = build_vit(arch, img_size=image_size)
        grid = image_size // vit.patch_size
        patch_dim = vit.patch_size**2 * 3
        decoder = MaeDecoder(
            vit.embed_dim, grid * grid, s.decoder_dim, s.decoder_depth, s.decoder_heads, patch_dim
        )
    data = imagenet_normalise(
        torch.cat([to_unit_tensor(images[i : i + 256], image_size) for i in range(0, n, 256)])
    )
    dev = torch.device(device)
    vit.to(dev)
    decoder.to(dev)
    opt = _mae_optimizer(vit, decoder, s)
    steps_per_epoch = max(1, n // batch)
    total = steps_per_epoch * s.epochs
    warm = min(total, s.warmup_epochs * steps_per_epoch)
    lr_sched = np.concatenate(
        [
            np.linspace(s.lr / max(warm, 1), s.lr, warm),
            s.lr * 0.5 * (1 + np.cos(np.pi * np.arange(total - warm) / max(total - warm, 1))),
        ]
    )
    order_rng = np.random.default_rng(s.seed)
    gen = torch.Generator().manual_seed(s.seed)
    curve: list[dict[str, float]] = []
    vit.train()
    decoder.train()
    step = 0
    for epoch in range(s.epochs):
        order = order_rng.permutation(n)
        losses = []
        for b in range(steps_per_epoch):
            idx = torch.from_numpy(order[b * batch : (b + 1) * batch])
            x = data[idx]
            # 1. a horizontal flip for half of the frames (the only augmentation)
            flip = torch.rand(x.shape[0], generator=gen) < 0.5
            x = torch.where(flip.view(-1, 1, 1, 1), x.flip(-1), x).to(dev)
            # 2. hide mask_ratio of the patches of each frame; encode the CLS and the rest
            keep, mask, restore = (
                a.to(dev) for a in random_masking(x.shape[0], grid * grid, s.mask_ratio, gen)
            )
            latent = encode_visible(vit, x, keep)
            # 3. decode every patch; MSE on the hidden ones (normalised pixels)
            pred = decoder(latent, restore)
            loss = mae_loss(pred, patchify(x, vit.patch_size), mask, norm_pix=s.norm_pix_loss)
            if not torch.isfinite(loss):
                raise FloatingPointError(f"pretrain_mae: loss {loss.item()} at step {step}")
            for g in opt.param_groups:
                g["lr"] = float(lr_sched[step])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            losses.append(loss.item())
            step += 1
        row = {"epoch": epoch, "loss": float(np.mean(losses)), "lr": float(lr_sched[step - 1])}
        curve.append(row)
        say(f"MAE epoch {epoch + 1}/{s.epochs}: masked-patch loss {row['loss']:.4f}")
    state = {k: v.detach().cpu().clone().contiguous() for k, v in vit.state_dict().items()}
    return MaePretrainResult(arch=arch, image_size=image_size, backbone_state=state, curve=curve)


#: keys of an official MAE checkpoint that the frozen encoder does not use: the decoder and
#: its mask token (decoder width), kept only in the "visualize" releases
_MAE_DECODER = ("decoder_", "mask_token")


def load_mae_checkpoint(model: DinoVisionTransformer, path: str | Path) -> DinoVisionTransformer:
    """Load an official MAE encoder checkpoint (timm ViT names, "model" wrapper) into `model`.

    The decoder keys are dropped; the DINOv2 architecture's LayerScale gammas, which a timm ViT
    does not have, are set to 1 (the identity: the same block as timm's) and its mask token to
    0 (unused by frozen extraction). Any other missing, unexpected or shape-mismatched key is
    refused with a ValueError naming the file and every such key.
    """
    path = Path(path)
    sd = unwrap_state_dict(load_tensors(path), where=str(path))
    sd = {k: v for k, v in sd.items() if not k.startswith(_MAE_DECODER)}
    # MAE's own resize (its util/pos_embed.py interpolate_pos_embed): bicubic to an exact size
    fit_pos_embed(sd, model, offset=0.0, antialias=False)
    own = model.state_dict()
    for k, v in own.items():
        if k not in sd and (k.endswith((".ls1.gamma", ".ls2.gamma"))):
            sd[k] = torch.ones_like(v)
    sd.setdefault("mask_token", torch.zeros_like(own["mask_token"]))
    problems = state_dict_mismatch(own, sd)
    if problems:
        raise ValueError(
            f"{path}: MAE checkpoint does not fit the ViT (embed_dim {model.embed_dim}, depth "
            f"{len(model.blocks)}, patch {model.patch_size}); {problems}. "
            "Name the matching arch (tacgen_lib.features.archs.ARCHS; official MAE releases "
            "use a 16-pixel patch: vit_base_p16) and an image_size that is a multiple of it."
        )
    model.load_state_dict({k: v.to(own[k].dtype) for k, v in sd.items()}, strict=True)
    return model.eval()
