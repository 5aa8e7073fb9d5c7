"""DINOv2-architecture ViT: official key format, loader refusals, pos-embed interpolation."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from tacgen_lib.features.vit import ARCHS, Attention, build_vit, interpolate_pos_embed
from tacgen_lib.features.vit_checkpoint import load_backbone, load_pretrained, save_backbone


def official_shapes(dim: int, depth: int, grid: int, regs: int = 0) -> dict[str, tuple]:
    """Key -> shape of an official DINOv2 ViT/14 `*_pretrain.pth`, written out independently
    of tacgen_lib from the published checkpoint layout (mlp_ratio 4, LayerScale, qkv bias)."""
    shapes: dict[str, tuple] = {
        "cls_token": (1, 1, dim),
        "pos_embed": (1, 1 + grid * grid, dim),
        "mask_token": (1, dim),
        "patch_embed.proj.weight": (dim, 3, 14, 14),
        "patch_embed.proj.bias": (dim,),
        "norm.weight": (dim,),
        "norm.bias": (dim,),
    }
    if regs:
        shapes["register_tokens"] = (1, regs, dim)
    for i in range(depth):
        p = f"blocks.{i}."
        shapes |= {
            p + "norm1.weight": (dim,),
            p + "norm1.bias": (dim,),
            p + "attn.qkv.weight": (3 * dim, dim),
            p + "attn.qkv.bias": (3 * dim,),
            p + "attn.proj.weight": (dim, dim),
            p + "attn.proj.bias": (dim,),
            p + "ls1.gamma": (dim,),
            p + "norm2.weight": (dim,),
            p + "norm2.bias": (dim,),
            p + "mlp.fc1.weight": (4 * dim, dim),
            p + "mlp.fc1.bias": (4 * dim,),
            p + "mlp.fc2.weight": (dim, 4 * dim),
            p + "mlp.fc2.bias": (dim,),
            p + "ls2.gamma": (dim,),
        }
    return shapes


def random_checkpoint(shapes: dict[str, tuple], seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return {k: 0.02 * torch.randn(s, generator=g) for k, s in shapes.items()}


def _images(b: int, h: int, w: int, seed: int = 0) -> torch.Tensor:
    return torch.randn(b, 3, h, w, generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize(("arch", "regs"), [("vit_small", 0), ("vit_base", 0), ("vit_small", 4)])
def test_state_dict_matches_official_key_format(arch, regs):
    cfg = ARCHS[arch]
    with torch.device("meta"):  # shapes only: skip the (slow) weight init
        model = build_vit(arch, img_size=518, num_register_tokens=regs)
    got = {k: tuple(v.shape) for k, v in model.state_dict().items()}
    assert got == official_shapes(cfg.embed_dim, cfg.depth, 37, regs)


def test_official_vits14_format_checkpoint_loads_and_runs(tmp_path):
    sd = random_checkpoint(official_shapes(384, 12, 37))
    path = tmp_path / "dinov2_vits14_pretrain.pth"
    torch.save(sd, path)
    with torch.device("meta"):
        model = build_vit("vit_small", img_size=518)
    model = load_pretrained(model.to_empty(device="cpu"), path)
    for k, v in model.state_dict().items():
        assert torch.equal(v, sd[k]), k
    out = model.forward_features(_images(2, 56, 42))
    assert out["x_norm_clstoken"].shape == (2, 384)
    assert out["x_norm_patchtokens"].shape == (2, 4 * 3, 384)
    assert torch.isfinite(out["x_norm_patchtokens"]).all()


def test_wrapped_training_checkpoint_with_backbone_prefix_loads(tmp_path):
    cfg = ARCHS["vit_tiny"]
    sd = random_checkpoint(official_shapes(cfg.embed_dim, cfg.depth, 4))
    wrapped = {
        "teacher": {f"backbone.{k}": v for k, v in sd.items()}
        | {"dino_head.mlp.0.weight": torch.zeros(8, cfg.embed_dim)},
        "model": {"unrelated": torch.zeros(1)},
        "iteration": 10,
    }
    torch.save(wrapped, tmp_path / "train.pth")
    model = load_pretrained(build_vit("vit_tiny", img_size=56), tmp_path / "train.pth")
    assert torch.equal(model.cls_token, sd["cls_token"])
    torch.save({"model": {f"module.{k}": v for k, v in sd.items()}}, tmp_path / "ddp.pth")
    model = load_pretrained(build_vit("vit_tiny", img_size=56), tmp_path / "ddp.pth")
    assert torch.equal(model.blocks[3].ls2.gamma, sd["blocks.3.ls2.gamma"])


def test_missing_and_unexpected_keys_are_listed(tmp_path):
    cfg = ARCHS["vit_tiny"]
    sd = random_checkpoint(official_shapes(cfg.embed_dim, cfg.depth, 4))
    del sd["blocks.2.ls1.gamma"]
    sd["blocks.2.attn.q_norm.weight"] = torch.zeros(cfg.embed_dim)
    torch.save(sd, tmp_path / "bad.pth")
    with pytest.raises(ValueError) as err:
        load_pretrained(build_vit("vit_tiny", img_size=56), tmp_path / "bad.pth")
    msg = str(err.value)
    assert "missing keys (1): ['blocks.2.ls1.gamma']" in msg
    assert "unexpected keys (1): ['blocks.2.attn.q_norm.weight']" in msg
    assert "bad.pth" in msg


def test_shape_mismatch_is_listed(tmp_path):
    # a vit_small checkpoint into a vit_tiny model: every width-dependent key mismatches
    torch.save(random_checkpoint(official_shapes(384, 6, 4)), tmp_path / "wide.pth")
    with pytest.raises(ValueError, match=r"shape mismatches \(\d+\):.*cls_token: checkpoint"):
        load_pretrained(build_vit("vit_tiny", img_size=56), tmp_path / "wide.pth")


def test_register_count_must_match(tmp_path):
    cfg = ARCHS["vit_tiny"]
    torch.save(random_checkpoint(official_shapes(cfg.embed_dim, cfg.depth, 4)), tmp_path / "p.pth")
    with pytest.raises(ValueError, match="missing keys.*register_tokens"):
        load_pretrained(
            build_vit("vit_tiny", img_size=56, num_register_tokens=4), tmp_path / "p.pth"
        )


def test_pos_embed_is_interpolated_to_the_model_grid_on_load(tmp_path):
    cfg = ARCHS["vit_tiny"]
    sd = random_checkpoint(official_shapes(cfg.embed_dim, cfg.depth, 37))
    # a constant field must stay constant under bicubic resampling
    sd["pos_embed"][:, 1:] = 0.5
    torch.save(sd, tmp_path / "p.pth")
    model = load_pretrained(build_vit("vit_tiny", img_size=112), tmp_path / "p.pth")
    assert model.pos_embed.shape == (1, 1 + 8 * 8, cfg.embed_dim)
    assert torch.equal(model.pos_embed[:, :1], sd["pos_embed"][:, :1])
    torch.testing.assert_close(model.pos_embed[:, 1:], torch.full((1, 64, cfg.embed_dim), 0.5))


@pytest.mark.parametrize(("h", "w"), [(14, 14), (28, 56), (56, 56), (112, 84), (224, 224)])
@pytest.mark.parametrize("regs", [0, 4])
def test_forward_interpolates_pos_encoding_to_any_grid(h, w, regs):
    torch.manual_seed(0)
    model = build_vit("vit_tiny", img_size=56, num_register_tokens=regs).eval()
    pe = model.interpolate_pos_encoding(h // 14, w // 14)
    assert pe.shape == (1, 1 + (h // 14) * (w // 14), model.embed_dim)
    with torch.inference_mode():
        out = model.forward_features(_images(2, h, w))
    assert out["x_norm_patchtokens"].shape == (2, (h // 14) * (w // 14), model.embed_dim)
    assert out["x_norm_regtokens"].shape == (2, regs, model.embed_dim)
    assert out["x_prenorm"].shape[1] == 1 + regs + (h // 14) * (w // 14)


def test_native_grid_pos_encoding_is_the_parameter():
    torch.manual_seed(0)
    model = build_vit("vit_tiny", img_size=56)
    assert torch.equal(model.interpolate_pos_encoding(4, 4), model.pos_embed.detach())


@pytest.mark.parametrize("regs", [0, 4])
def test_pos_embed_fitted_on_load_is_the_one_the_checkpoint_grid_gives_at_forward(tmp_path, regs):
    # DINOv2 keeps the 37 x 37 grid and resamples it at each forward (offset 0.1, or antialias
    # for register models); resampling once on load with the model's own settings must give
    # the very same embeddings (the same computation on the same array: bit-identical)
    cfg = ARCHS["vit_tiny"]
    torch.save(
        random_checkpoint(official_shapes(cfg.embed_dim, cfg.depth, 37, regs)), tmp_path / "p.pth"
    )
    native = load_pretrained(
        build_vit("vit_tiny", img_size=518, num_register_tokens=regs), tmp_path / "p.pth"
    )
    fitted = load_pretrained(
        build_vit("vit_tiny", img_size=112, num_register_tokens=regs), tmp_path / "p.pth"
    )
    assert (fitted.interpolate_offset, fitted.interpolate_antialias) == (
        (0.0, True) if regs else (0.1, False)
    )
    with torch.no_grad():
        assert torch.equal(fitted.pos_embed, native.interpolate_pos_encoding(8, 8))
    with pytest.raises(ValueError, match="square grid"):
        interpolate_pos_embed(torch.zeros(1, 10, 3), (2, 2), offset=0.1, antialias=False)


def test_attention_matches_float64_sdpa_reference():
    torch.manual_seed(1)
    attn = Attention(48, 3).double()
    x = 4 * torch.randn(2, 9, 48, dtype=torch.float64)
    qkv = attn.qkv(x).reshape(2, 9, 3, 3, 16).permute(2, 0, 3, 1, 4)
    ref = F.scaled_dot_product_attention(qkv[0], qkv[1], qkv[2])
    ref = attn.proj(ref.transpose(1, 2).reshape(2, 9, 48))
    torch.testing.assert_close(attn(x), ref, rtol=1e-12, atol=1e-12)


def test_mask_token_replaces_masked_patches():
    torch.manual_seed(2)
    model = build_vit("vit_tiny", img_size=28)
    x = _images(1, 28, 28)
    masks = torch.tensor([[True, False, False, True]])
    tok = model.prepare_tokens_with_masks(x, masks)
    pe = model.interpolate_pos_encoding(2, 2)
    torch.testing.assert_close(tok[0, 1], model.mask_token[0] + pe[0, 1])
    torch.testing.assert_close(tok[0, 4], model.mask_token[0] + pe[0, 4])
    assert not torch.allclose(tok[0, 2], model.mask_token[0] + pe[0, 2])


def test_round_trip_save_load_gives_identical_outputs(tmp_path):
    torch.manual_seed(3)
    model = build_vit("vit_tiny", img_size=56, num_register_tokens=4).eval()
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.01 * torch.randn_like(p))
    save_backbone(model, tmp_path / "b" / "backbone.pth")
    loaded = load_backbone(tmp_path / "b" / "backbone.pth").eval()
    assert loaded.num_register_tokens == 4 and loaded.grid_size == 4
    x = _images(3, 70, 56)
    with torch.inference_mode():
        a, b = model.forward_features(x), loaded.forward_features(x)
    assert torch.equal(a["x_norm_clstoken"], b["x_norm_clstoken"])
    assert torch.equal(a["x_norm_patchtokens"], b["x_norm_patchtokens"])
    assert not (tmp_path / "b" / "backbone.pth.tmp").exists()


def test_load_backbone_refuses_unknown_width(tmp_path):
    torch.save(random_checkpoint(official_shapes(96, 2, 4)), tmp_path / "odd.pth")
    with pytest.raises(ValueError, match="no known arch with embed_dim 96, depth 2 and patch 14"):
        load_backbone(tmp_path / "odd.pth")


def test_inputs_not_multiple_of_patch_are_refused():
    model = build_vit("vit_tiny", img_size=56)
    with pytest.raises(ValueError, match="not a multiple of the patch size 14"):
        model(_images(1, 50, 56))
    with pytest.raises(ValueError, match="unknown ViT arch"):
        build_vit("vit_huge")
    assert math.isclose(model.blocks[0].attn.scale, 64**-0.5)
