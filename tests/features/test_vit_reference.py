"""Official checkpoints give their own code's features: the project's ViT, loaded from a state
dict with the published keys and shapes (DINOv2 ViT-S/14, ViT-B/14, a register model; MAE's
ViT-B/16 encoder), against an independent float64 forward written here from the published
architectures (DINOv2's `DinoVisionTransformer` with its `interpolate_pos_encoding`; MAE's timm
ViT encoder with its `interpolate_pos_embed`).

The reference is plain: explicit matmuls, layer norms, softmax and an erf GELU (scipy's erf), and its own
bicubic resampling (the two kernels PyTorch's `interpolate` applies: Keys' cubic with a = -0.75
on source coordinates driven by the scale, and the antialiased one with a = -0.5 and a support
widened by the scale), so nothing of `tacgen_lib` is reused.

Weights are seeded random values at scales that let every part reach the CLS token (attention
and MLP weights of unit gain, LayerScale around 0.1, position embeddings of size 0.5), so a
position grid resampled with the wrong offset or antialiasing moves the features well above
the tolerance.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest
import torch
from scipy.special import erf

from tacgen_lib.features.mae import load_mae_checkpoint
from tacgen_lib.features.vit import build_vit, interpolate_pos_embed
from tacgen_lib.features.vit_checkpoint import load_pretrained

#: agreement required of float32 features against the float64 reference
TOL = 1e-5

# --------------------------------------------------------------------------- published layouts


def dinov2_shapes(dim: int, depth: int, regs: int, patch: int = 14, grid: int = 37) -> dict:
    """Key -> shape of a DINOv2 hub checkpoint (`dinov2_vit{s,b}14[_reg4]_pretrain.pth`):
    518-pixel position grid (37 x 37), LayerScale, qkv bias, MLP ratio 4, no head."""
    shapes = {
        "cls_token": (1, 1, dim),
        "pos_embed": (1, 1 + grid * grid, dim),
        "mask_token": (1, dim),
        "patch_embed.proj.weight": (dim, 3, patch, patch),
        "patch_embed.proj.bias": (dim,),
        "norm.weight": (dim,),
        "norm.bias": (dim,),
    }
    if regs:
        shapes["register_tokens"] = (1, regs, dim)
    for i in range(depth):
        for name, shape in (
            ("norm1.weight", (dim,)),
            ("norm1.bias", (dim,)),
            ("attn.qkv.weight", (3 * dim, dim)),
            ("attn.qkv.bias", (3 * dim,)),
            ("attn.proj.weight", (dim, dim)),
            ("attn.proj.bias", (dim,)),
            ("ls1.gamma", (dim,)),
            ("norm2.weight", (dim,)),
            ("norm2.bias", (dim,)),
            ("mlp.fc1.weight", (4 * dim, dim)),
            ("mlp.fc1.bias", (4 * dim,)),
            ("mlp.fc2.weight", (dim, 4 * dim)),
            ("mlp.fc2.bias", (dim,)),
            ("ls2.gamma", (dim,)),
        ):
            shapes[f"blocks.{i}.{name}"] = shape
    return shapes


def mae_shapes(dim: int = 768, depth: int = 12, patch: int = 16, grid: int = 14) -> dict:
    """Key -> shape of MAE's `mae_pretrain_vit_base.pth` encoder (timm names: no LayerScale,
    no mask token; 224-pixel grid of 14 x 14)."""
    shapes = dinov2_shapes(dim, depth, 0, patch=patch, grid=grid)
    return {k: s for k, s in shapes.items() if not k.endswith(".gamma") and k != "mask_token"}


def seeded_weights(shapes: dict, seed: int) -> dict[str, torch.Tensor]:
    """Random float32 values at scales where every tensor moves the output (see the module)."""
    g = torch.Generator().manual_seed(seed)

    def randn(shape, std, mean=0.0):  # uniform of that std: one pass, faster than a normal
        half = std * math.sqrt(3.0)
        return torch.empty(shape).uniform_(mean - half, mean + half, generator=g)

    sd = {}
    for k, shape in shapes.items():
        if k.endswith("gamma"):
            sd[k] = randn(shape, 0.03, 0.1)
        elif k.endswith(("norm1.weight", "norm2.weight")) or k == "norm.weight":
            sd[k] = randn(shape, 0.1, 1.0)
        elif k.endswith("bias"):
            sd[k] = randn(shape, 0.02)
        elif k.endswith("weight"):  # linear and patch layers: unit gain
            sd[k] = randn(shape, 1.0 / math.sqrt(math.prod(shape[1:])))
        elif k == "pos_embed":
            sd[k] = randn(shape, 0.5)
        else:  # cls, register and mask tokens
            sd[k] = randn(shape, 1.0)
    assert set(sd) == set(shapes)
    return sd


# --------------------------------------------------------------------------- reference


def _cubic(x: float, a: float) -> float:
    """Keys' cubic convolution kernel."""
    x = abs(x)
    if x <= 1:
        return (a + 2) * x**3 - (a + 3) * x**2 + 1
    if x < 2:
        return a * x**3 - 5 * a * x**2 + 8 * a * x - 4 * a
    return 0.0


def bicubic_matrix(n_in: int, n_out: int, step: float, *, antialias: bool) -> np.ndarray:
    """(n_out, n_in) weights of one axis of a bicubic resize whose output pixel i samples the
    input at (i + 0.5) * step - 0.5 (`step`: input pixels per output pixel).

    Plain: Keys' kernel (a = -0.75) on the 4 nearest pixels, edges clamped. Antialiased:
    Keys' kernel with a = -0.5 stretched by `step` when shrinking, weights normalised."""
    w = np.zeros((n_out, n_in))
    for i in range(n_out):
        if not antialias:
            src = (i + 0.5) * step - 0.5
            x0 = math.floor(src)
            t = src - x0
            for k in range(-1, 3):
                w[i, min(max(x0 + k, 0), n_in - 1)] += _cubic(t - k, -0.75)
            continue
        centre = step * (i + 0.5)
        support = 2.0 * max(step, 1.0)
        lo = max(int(centre - support + 0.5), 0)
        hi = min(int(centre + support + 0.5), n_in)
        taps = np.array([_cubic((j - centre + 0.5) / max(step, 1.0), -0.5) for j in range(lo, hi)])
        w[i, lo:hi] = taps / taps.sum()
    return w


def dinov2_positions(pos_embed: np.ndarray, rows: int, cols: int, offset: float, aa: bool):
    """DINOv2's `interpolate_pos_encoding` for a rows x cols patch grid: the CLS position as
    is, the M x M grid resampled (scale (rows + offset) / M when offset > 0, else to the
    size; antialiasing as the model says)."""
    m = math.isqrt(pos_embed.shape[1] - 1)
    grid = pos_embed[0, 1:].reshape(m, m, -1)
    if (rows, cols) != (m, m):
        step_r = m / (rows + offset) if offset else m / rows
        step_c = m / (cols + offset) if offset else m / cols
        wr = bicubic_matrix(m, rows, step_r, antialias=aa)
        wc = bicubic_matrix(m, cols, step_c, antialias=aa)
        grid = np.einsum("ri,ijd,cj->rcd", wr, grid, wc)
    return np.concatenate([pos_embed[0, :1], grid.reshape(rows * cols, -1)])[None]


def _layer_norm(x, w, b):
    mean = x.mean(-1, keepdims=True)
    var = ((x - mean) ** 2).mean(-1, keepdims=True)
    return (x - mean) / np.sqrt(var + 1e-6) * w + b


def _gelu(x):
    return 0.5 * x * (1.0 + erf(x / math.sqrt(2.0)))


def reference_forward(
    sd: dict, images: np.ndarray, *, heads: int, offset: float, aa: bool, layerscale: bool
) -> np.ndarray:
    """Normalised tokens (B, 1 + R + N, D) of a DINOv2 / timm ViT in float64, from its state
    dict: patch projection, CLS, position embeddings, registers after CLS, pre-norm blocks
    x + ls1 * attn(norm1 x), x + ls2 * mlp(norm2 x), final norm."""
    p = {k: v.double().numpy() for k, v in sd.items()}
    b, _, h, w = images.shape
    dim, _, ps, _ = p["patch_embed.proj.weight"].shape
    rows, cols = h // ps, w // ps
    patches = images.reshape(b, 3, rows, ps, cols, ps).transpose(0, 2, 4, 1, 3, 5)
    patches = patches.reshape(b, rows * cols, 3 * ps * ps)
    tokens = patches @ p["patch_embed.proj.weight"].reshape(dim, -1).T + p["patch_embed.proj.bias"]
    x = np.concatenate([np.broadcast_to(p["cls_token"], (b, 1, dim)), tokens], axis=1)
    x = x + dinov2_positions(p["pos_embed"], rows, cols, offset, aa)
    if "register_tokens" in p:
        regs = np.broadcast_to(p["register_tokens"], (b, p["register_tokens"].shape[1], dim))
        x = np.concatenate([x[:, :1], regs, x[:, 1:]], axis=1)
    depth = 1 + max(int(k.split(".")[1]) for k in p if k.startswith("blocks."))
    hd = dim // heads
    for i in range(depth):
        blk = {
            k.removeprefix(f"blocks.{i}."): v for k, v in p.items() if k.startswith(f"blocks.{i}.")
        }
        q = blk.__getitem__
        ls1 = q("ls1.gamma") if layerscale else 1.0
        ls2 = q("ls2.gamma") if layerscale else 1.0
        y = _layer_norm(x, q("norm1.weight"), q("norm1.bias"))
        qkv = (y @ q("attn.qkv.weight").T + q("attn.qkv.bias")).reshape(b, -1, 3, heads, hd)
        qq, kk, vv = (qkv[:, :, j].transpose(0, 2, 1, 3) for j in range(3))  # (B, H, N, hd)
        logits = qq @ kk.transpose(0, 1, 3, 2) / math.sqrt(hd)
        att = np.exp(logits - logits.max(-1, keepdims=True))
        att /= att.sum(-1, keepdims=True)
        o = (att @ vv).transpose(0, 2, 1, 3).reshape(b, -1, dim)
        x = x + ls1 * (o @ q("attn.proj.weight").T + q("attn.proj.bias"))
        y = _layer_norm(x, q("norm2.weight"), q("norm2.bias"))
        hid = _gelu(y @ q("mlp.fc1.weight").T + q("mlp.fc1.bias"))
        x = x + ls2 * (hid @ q("mlp.fc2.weight").T + q("mlp.fc2.bias"))
    return _layer_norm(x, p["norm.weight"], p["norm.bias"])


def _images(b: int, size: int, seed: int) -> torch.Tensor:
    return torch.randn(b, 3, size, size, generator=torch.Generator().manual_seed(seed))


# --------------------------------------------------------------------------- tests


def test_bicubic_reference_is_torch_interpolate():
    """The reference's kernels are the ones PyTorch applies (both DINOv2 modes and MAE's)."""
    m = 37
    field = torch.randn(1, 3, m, m, generator=torch.Generator().manual_seed(0))
    ref_in = field[0].double().numpy().transpose(1, 2, 0)
    for g in (4, 16, 23):
        for offset, aa in ((0.1, False), (0.0, True), (0.0, False)):
            kw = {"scale_factor": ((g + offset) / m,) * 2} if offset else {"size": (g, g)}
            got = torch.nn.functional.interpolate(field, mode="bicubic", antialias=aa, **kw)
            step = m / (g + offset)
            w = bicubic_matrix(m, g, step, antialias=aa)
            ref = np.einsum("ri,ijd,cj->rcd", w, ref_in, w)
            # float32 source coordinates: a few 1e-6 on a unit field
            np.testing.assert_allclose(got[0].numpy().transpose(1, 2, 0), ref, atol=5e-5)


@pytest.mark.parametrize(
    ("arch", "dim", "depth", "heads", "regs", "size"),
    [
        ("vit_small", 384, 12, 6, 0, 112),  # dinov2_vits14
        ("vit_base", 768, 12, 12, 0, 56),  # dinov2_vitb14
        ("vit_small", 384, 12, 6, 4, 112),  # dinov2_vits14_reg4: antialiased, no offset
    ],
)
def test_official_dinov2_checkpoint_gives_dinov2_features(
    tmp_path, arch, dim, depth, heads, regs, size
):
    shapes = dinov2_shapes(dim, depth, regs)
    assert len(shapes) == 7 + (1 if regs else 0) + 14 * depth  # 175 keys (+ registers)
    sd = seeded_weights(shapes, seed=dim + regs)
    path = tmp_path / "dinov2_pretrain.pth"
    torch.save(sd, path)
    # as tacgen_lib.features.backbones builds it: the arch at the run's image size, then loaded
    with torch.device("meta"):
        model = build_vit(arch, img_size=size, num_register_tokens=regs)
    model = load_pretrained(model.to_empty(device="cpu"), path).eval()
    offset, aa = (0.0, True) if regs else (0.1, False)  # DINOv2's hub settings per model kind
    assert (model.interpolate_offset, model.interpolate_antialias) == (offset, aa)

    g = size // 14
    ref_pos = dinov2_positions(sd["pos_embed"].double().numpy(), g, g, offset, aa)
    np.testing.assert_allclose(model.pos_embed.detach().numpy(), ref_pos, atol=TOL)

    x = _images(1, size, seed=1)
    with torch.inference_mode():
        out = model.forward_features(x)
    ref = reference_forward(
        sd, x.double().numpy(), heads=heads, offset=offset, aa=aa, layerscale=True
    )
    np.testing.assert_allclose(out["x_norm_clstoken"].numpy(), ref[:, 0], atol=TOL, rtol=0)
    np.testing.assert_allclose(out["x_norm_regtokens"].numpy(), ref[:, 1 : 1 + regs], atol=TOL)
    np.testing.assert_allclose(out["x_norm_patchtokens"].numpy(), ref[:, 1 + regs :], atol=TOL)

    # the grid resampled as the other model kind resamples it is far from DINOv2's
    other = dinov2_positions(sd["pos_embed"].double().numpy(), g, g, 0.1 - offset, not aa)
    assert np.abs(other - ref_pos).max() > 1000 * TOL


def test_official_mae_checkpoint_with_training_entries_gives_mae_features(tmp_path):
    """MAE's ViT-B/16 encoder (150 keys in "model"), saved as its training code saves it (with
    optimizer, epoch, scaler and an argparse `args`), loads and gives the timm ViT's features;
    at 64 pixels its 14 x 14 grid is resized as MAE's interpolate_pos_embed does (to the size,
    no offset, no antialiasing)."""
    shapes = mae_shapes()
    assert len(shapes) == 150
    sd = seeded_weights(shapes, seed=5)
    path = tmp_path / "mae_pretrain_vit_base.pth"
    args = argparse.Namespace(model="mae_vit_base_patch16", mask_ratio=0.75, norm_pix_loss=True)
    torch.save(
        {
            "model": sd,
            "optimizer": {"state": {}, "param_groups": [{"lr": 1.5e-4, "params": [0, 1]}]},
            "epoch": 799,
            "scaler": {"scale": 65536.0, "growth_factor": 2.0},
            "args": args,
        },
        path,
    )
    with torch.device("meta"):
        model = build_vit("vit_base_p16", img_size=64)
    model = load_mae_checkpoint(model.to_empty(device="cpu"), path).eval()
    x = _images(1, 64, seed=2)
    with torch.inference_mode():
        got = model(x).numpy()
    ref = reference_forward(
        sd, x.double().numpy(), heads=12, offset=0.0, aa=False, layerscale=False
    )
    np.testing.assert_allclose(got, ref[:, 0], atol=TOL, rtol=0)


def test_interpolate_pos_embed_takes_the_callers_settings():
    """No silent default: a resize says which code's resampling it is."""
    field = torch.randn(1, 37 * 37, 4, generator=torch.Generator().manual_seed(3))
    with pytest.raises(TypeError):
        interpolate_pos_embed(field, (8, 8))  # type: ignore[call-arg]
    dino = interpolate_pos_embed(field, (8, 8), offset=0.1, antialias=False)
    reg = interpolate_pos_embed(field, (8, 8), offset=0.0, antialias=True)
    assert (dino - reg).abs().max() > 0.1
