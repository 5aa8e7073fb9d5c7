"""Backbone families: the ResNet (torchvision's shapes and names), MAE pretraining and its
checkpoint loader, making and reading any family's backbone, the families' config, their probes
and their report sentences."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch
from pretrain_checks import assert_loss_falls, assert_same_backbone
from probe_worlds import synthetic_family_rows
from rounding import reordered_sum_atol
from snakemake_run import validated

from tacgen_lib.features.archs import ARCHS, RESNET_ARCHS, arch_family, feature_dim
from tacgen_lib.features.backbones import make_backbone, read_backbone
from tacgen_lib.features.extract import extract_features, imagenet_normalise, to_unit_tensor
from tacgen_lib.features.families import BackboneSpec, FamilySettings, check_backbone
from tacgen_lib.features.mae import (
    encode_visible,
    load_mae_checkpoint,
    mae_loss,
    patchify,
    pretrain_mae,
    random_masking,
)
from tacgen_lib.features.resnet import (
    build_resnet,
    load_resnet_checkpoint,
    random_resnet,
    resnet_from_state_dict,
)
from tacgen_lib.features.settings import (
    DinoSettings,
    FeatureSettings,
    MaeSettings,
    SimclrSettings,
    pretraining_corpora,
)
from tacgen_lib.features.vit import build_vit
from tacgen_lib.features.vit_checkpoint import save_backbone
from tacgen_lib.io.config import ConfigError
from tacgen_lib.probes.backbone_families import (
    FAMILY_COLUMNS,
    backbone_family_rows,
    rows_from_probes,
)
from tacgen_lib.report.backbones import family_sentences, family_table


def resnet_tiny_atol(ref) -> float:
    """`reordered_sum_atol` of a resnet_tiny forward (a loaded copy may run other kernels):
    its largest sums are the 3 x 3 convolutions over the last stage's channels; the stem, two
    convolutions per block and the pool chain them."""
    arch = RESNET_ARCHS["resnet_tiny"]
    return reordered_sum_atol(ref, terms=9 * arch.widths[-1], depth=2 + 2 * sum(arch.blocks))


def vit_tiny_atol(ref) -> float:
    """`reordered_sum_atol` of a vit_tiny forward: its largest sums are the MLP's second layer
    over mlp_ratio x embed_dim units; each block chains eight (two LayerNorms, qkv, q.k,
    attention x v, the projection, the MLP's two layers), after the patch embedding and
    before the last norm."""
    arch = ARCHS["vit_tiny"]
    return reordered_sum_atol(
        ref, terms=int(arch.mlp_ratio * arch.embed_dim), depth=2 + 8 * arch.depth
    )


# ----------------------------------------------------------------------------- ResNet

#: torchvision.models.resnet18(): 11,689,512 parameters, of which the 1000-class fc has
#: 512 * 1000 + 1000 (published in torchvision's model table; torchvision cannot be imported
#: beside this project's CPU torch)
TORCHVISION_RESNET18_PARAMS = 11_689_512
TORCHVISION_RESNET18_FC = 512 * 1000 + 1000


def test_resnet18_has_torchvision_parameter_count_and_names():
    model = build_resnet("resnet18")
    n = sum(p.numel() for p in model.parameters())
    assert n == TORCHVISION_RESNET18_PARAMS - TORCHVISION_RESNET18_FC
    keys = list(model.state_dict())
    # torchvision's resnet18 state dict has 122 entries; 120 without fc.weight and fc.bias
    assert len(keys) == 120
    for name in (
        "conv1.weight",
        "bn1.running_var",
        "bn1.num_batches_tracked",
        "layer1.0.conv1.weight",
        "layer1.1.bn2.bias",
        "layer2.0.downsample.0.weight",
        "layer2.0.downsample.1.running_mean",
        "layer4.1.conv2.weight",
    ):
        assert name in keys, name
    assert "layer1.0.downsample.0.weight" not in keys  # stride 1, same width: no projection


def test_resnet_pools_agree_and_give_the_last_stage_width():
    model = random_resnet("resnet_tiny", seed=0)
    images = np.random.default_rng(0).integers(0, 256, (5, 40, 48, 3), dtype=np.uint8)
    cls = extract_features(model, images, image_size=56, pool="cls", device="cpu", batch_size=64)
    mean = extract_features(
        model, images, image_size=56, pool="mean_patch", device="cpu", batch_size=64
    )
    assert (
        cls.shape == (5, feature_dim("resnet_tiny")) == (5, RESNET_ARCHS["resnet_tiny"].widths[-1])
    )
    np.testing.assert_allclose(cls, mean, rtol=1e-6, atol=1e-7)  # two reductions of one map


def _stage_statistics_float64(model, x: torch.Tensor) -> np.ndarray:
    """Reference: each stage's maps taken with forward hooks, in float64 numpy: the population
    std over space of stages 1-3, then the mean of stage 4."""
    maps = []
    hooks = [
        getattr(model, f"layer{i}").register_forward_hook(lambda _m, _i, out: maps.append(out))
        for i in range(1, 5)
    ]
    with torch.no_grad():
        model(x)
    for h in hooks:
        h.remove()
    parts = []
    for i, m in enumerate(maps):
        a = m.double().numpy().reshape(m.shape[0], m.shape[1], -1)
        parts.append(a.mean(axis=2) if i == 3 else a.std(axis=2))
    return np.concatenate(parts, axis=1)


@pytest.mark.parametrize("size", [28, 56, 70])
def test_stages_pool_is_every_stage_mean_and_std_against_float64(size):
    model = random_resnet("resnet_tiny", seed=1)
    images = np.random.default_rng(size).integers(0, 256, (6, 40, 48, 3), dtype=np.uint8)
    got = extract_features(
        model, images, image_size=size, batch_size=4, pool="stages", device="cpu"
    )
    assert got.shape == (6, sum(RESNET_ARCHS["resnet_tiny"].widths)) and got.dtype == np.float32
    x = imagenet_normalise(to_unit_tensor(images, size))
    np.testing.assert_allclose(got, _stage_statistics_float64(model, x), rtol=1e-4, atol=1e-5)
    # the last stage's mean is the cls pool
    last = sum(RESNET_ARCHS["resnet_tiny"].widths[:3])
    np.testing.assert_allclose(
        got[:, last:],
        extract_features(model, images, image_size=size, pool="cls", device="cpu", batch_size=64),
        rtol=1e-5,
        atol=1e-6,
    )
    np.testing.assert_array_equal(
        got,
        extract_features(model, images, image_size=size, batch_size=4, pool="stages", device="cpu"),
    )


def test_stages_pool_refuses_a_vit_and_an_unknown_pool():
    images = np.zeros((2, 28, 28, 3), dtype=np.uint8)
    vit = build_vit("vit_tiny", img_size=28)
    with pytest.raises(ValueError, match="pool 'stages' needs a ResNet, got DinoVisionTransformer"):
        extract_features(vit, images, image_size=28, pool="stages", device="cpu", batch_size=64)
    with pytest.raises(ValueError, match="pool must be one of"):
        extract_features(vit, images, image_size=28, pool="max", device="cpu", batch_size=64)


def test_resnet_checkpoint_drops_fc_and_names_missing_and_extra_keys():
    sd = random_resnet("resnet_tiny", seed=1).state_dict()
    with_fc = {**sd, "fc.weight": torch.zeros(1000, 128), "fc.bias": torch.zeros(1000)}
    model = resnet_from_state_dict(with_fc, where="ckpt.pth")
    assert model.state_dict().keys() == sd.keys()  # no fc
    for k, v in sd.items():
        assert torch.equal(model.state_dict()[k], v), k
    x = torch.rand(2, 3, 56, 56)
    with torch.no_grad():
        got, want = model(x), random_resnet("resnet_tiny", seed=1)(x)
    # a loaded network against a built one: the same weights, maybe other kernels
    torch.testing.assert_close(got, want, rtol=0, atol=resnet_tiny_atol(want))
    broken = {k: v for k, v in sd.items() if k != "layer2.0.bn1.weight"}
    broken["layer9.0.conv1.weight"] = torch.zeros(1)
    with pytest.raises(ValueError) as err:
        load_resnet_checkpoint(build_resnet("resnet_tiny"), broken, where="ckpt.pth")
    msg = str(err.value)
    assert "ckpt.pth" in msg and "layer2.0.bn1.weight" in msg and "layer9.0.conv1.weight" in msg
    with pytest.raises(ValueError, match="no known ResNet arch"):
        resnet_from_state_dict(
            {k: v for k, v in sd.items() if not k.startswith("layer4.")}
            | {"layer4.0.conv1.weight": torch.zeros(7, 64, 3, 3)},
            where="odd.pth",
        )


def test_arch_family_names_every_arch_and_refuses_unknown():
    assert {arch_family(a) for a in ARCHS} == {"vit"}
    assert {arch_family(a) for a in RESNET_ARCHS} == {"resnet"}
    with pytest.raises(ValueError, match="unknown backbone arch 'vgg16'"):
        arch_family("vgg16")


# ----------------------------------------------------------------------------- MAE


def test_patchify_matches_a_plain_loop():
    x = torch.randn(2, 3, 28, 42)
    got = patchify(x, 14)
    want = torch.stack(
        [
            torch.stack(
                [
                    x[b, :, i * 14 : (i + 1) * 14, j * 14 : (j + 1) * 14]
                    .permute(1, 2, 0)
                    .reshape(-1)
                    for i in range(2)
                    for j in range(3)
                ]
            )
            for b in range(2)
        ]
    )
    assert torch.equal(got, want)


@pytest.mark.parametrize("ratio", [0.0, 0.75, 0.99])
def test_random_masking_keeps_the_stated_share_and_restores_the_order(ratio):
    gen = torch.Generator().manual_seed(0)
    keep, mask, restore = random_masking(4, 16, ratio, gen)
    k = max(1, round(16 * (1 - ratio)))
    assert keep.shape == (4, k) and mask.shape == (4, 16)
    assert (mask.sum(dim=1) == 16 - k).all()
    for b in range(4):
        assert (mask[b, keep[b]] == 0).all()  # kept patches are not hidden
    shuffled = torch.argsort(restore, dim=1)
    assert torch.equal(torch.gather(shuffled, 1, restore), torch.arange(16).expand(4, -1))
    with pytest.raises(ValueError, match="mask_ratio"):
        random_masking(1, 4, 1.0, gen)


def test_mae_loss_counts_only_hidden_patches_and_normalises_per_patch():
    rng = torch.Generator().manual_seed(1)
    target = torch.randn(3, 8, 12, generator=rng) * 5 + 2
    pred = torch.randn(3, 8, 12, generator=rng)
    mask = torch.zeros(3, 8)
    mask[:, :3] = 1.0
    moved = pred.clone()
    moved[:, 3:] += 100.0  # visible patches: no effect on the loss
    for norm in (False, True):
        assert mae_loss(pred, target, mask, norm_pix=norm) == mae_loss(
            moved, target, mask, norm_pix=norm
        )
    # float64 reference of the normalised loss
    t = target.double()
    t = (t - t.mean(-1, keepdim=True)) / (t.var(-1, keepdim=True) + 1e-6).sqrt()
    ref = ((pred.double() - t) ** 2).mean(-1)[:, :3].mean()
    assert mae_loss(pred, target, mask, norm_pix=True).item() == pytest.approx(ref.item(), rel=1e-6)


def test_encoder_on_every_patch_equals_the_plain_forward():
    vit = build_vit("vit_tiny", img_size=28).eval()
    x = torch.randn(2, 3, 28, 28)
    keep = torch.arange(4).expand(2, -1)  # every patch visible, in order
    with torch.no_grad():
        got = encode_visible(vit, x, keep)
        want = vit.forward_features(x)
    # the same operations on the same tokens: within float32 rounding of a 6-block ViT
    torch.testing.assert_close(got[:, 0], want["x_norm_clstoken"], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(got[:, 1:], want["x_norm_patchtokens"], rtol=1e-5, atol=1e-5)


def _textures(n=24, size=28, seed=0):
    """Frames with structure a masked autoencoder can learn: stripes of random phase."""
    rng = np.random.default_rng(seed)
    yy = np.arange(size)[None, :, None]
    phase = rng.uniform(0, 2 * np.pi, (n, 1, 1))
    base = 127 + 100 * np.sin(yy / 3.0 + phase)
    img = np.repeat(base[..., None], size, axis=2).transpose(0, 1, 2, 3)[..., 0]
    img = np.stack([img, img[:, ::-1], img], axis=-1)
    return np.clip(img, 0, 255).astype(np.uint8)


def test_pretrain_mae_is_bit_identical_when_run_twice_and_its_loss_falls():
    frames = _textures()
    settings = MaeSettings.tiny(epochs=6, batch_size=8, lr=3e-3)
    torch.set_num_threads(1)
    one = pretrain_mae(frames, settings, arch="vit_tiny", image_size=28, device="cpu")
    two = pretrain_mae(frames, settings, arch="vit_tiny", image_size=28, device="cpu")
    assert_same_backbone(one, two)
    assert_loss_falls(one.curve, epochs=6)
    assert set(one.backbone_state) == set(build_vit("vit_tiny", img_size=28).state_dict())


def _timm_mae_state(model) -> dict:
    """An official-MAE-format state dict from a ViT: timm names (no LayerScale, no 1-D mask
    token) plus the decoder keys of the "visualize" releases."""
    sd = {
        k: v.clone()
        for k, v in model.state_dict().items()
        if not k.endswith(("ls1.gamma", "ls2.gamma")) and k != "mask_token"
    }
    sd["decoder_embed.weight"] = torch.zeros(16, model.embed_dim)
    sd["mask_token"] = torch.zeros(1, 1, 16)  # the decoder's, not the encoder's
    return {"model": sd}


def test_official_mae_checkpoint_loads_with_identity_layerscale(tmp_path):
    torch.manual_seed(0)
    src = build_vit("vit_tiny", img_size=28)
    with torch.no_grad():
        for blk in src.blocks:
            blk.ls1.gamma.fill_(1.0)
            blk.ls2.gamma.fill_(1.0)
    path = tmp_path / "mae_pretrain_vit_tiny.pth"
    torch.save(_timm_mae_state(src), path)
    got = load_mae_checkpoint(build_vit("vit_tiny", img_size=28), path)
    for k, v in src.state_dict().items():  # LayerScale 1 where the release has none
        assert torch.equal(got.state_dict()[k], v), k
    x = torch.randn(2, 3, 28, 28)
    with torch.no_grad():
        out, want = got(x), src.eval()(x)
    # a loaded network against the source: the same weights, maybe other kernels
    torch.testing.assert_close(out, want, rtol=0, atol=vit_tiny_atol(want))
    state = _timm_mae_state(src)["model"]
    del state["blocks.3.attn.qkv.weight"]
    state["head.weight"] = torch.zeros(10, 192)
    torch.save({"model": state}, path)
    with pytest.raises(ValueError) as err:
        load_mae_checkpoint(build_vit("vit_tiny", img_size=28), path)
    assert str(path) in str(err.value)
    assert "blocks.3.attn.qkv.weight" in str(err.value) and "head.weight" in str(err.value)


def test_mae_release_patch_of_16_needs_its_own_arch(tmp_path):
    p16 = build_vit("vit_base_p16", img_size=32)
    assert p16.patch_size == 16 and p16.grid_size == 2
    path = tmp_path / "mae_pretrain_vit_base.pth"
    torch.save(_timm_mae_state(p16), path)
    with pytest.raises(ValueError, match="shape mismatches.*patch_embed.proj.weight"):
        load_mae_checkpoint(build_vit("vit_base", img_size=28), path)
    load_mae_checkpoint(build_vit("vit_base_p16", img_size=32), path)


# ----------------------------------------------------------------------------- make / read


@pytest.mark.parametrize(
    "spec",
    [
        BackboneSpec("resnet_tiny", objective="random"),
        BackboneSpec("vit_tiny", objective="random"),
        BackboneSpec("vit_tiny", objective="dino"),  # 0 DINO epochs: the random init
        BackboneSpec("vit_tiny", objective="mae"),
        BackboneSpec("resnet_tiny", objective="simclr"),
    ],
    ids=lambda s: f"{s.arch}-{s.objective}",
)
def test_made_backbone_round_trips_through_its_saved_weights(spec, tmp_path):
    frames = _textures(n=8)
    calls = []

    def train_frames():
        calls.append(1)
        return frames

    model, curve, how = make_backbone(
        spec,
        image_size=28,
        dino=DinoSettings.tiny(epochs=0),
        mae=MaeSettings.tiny(epochs=1),
        frames=train_frames,
        simclr=SimclrSettings.tiny(),
        device="cpu",
    )
    pretrained = spec.objective in ("mae", "simclr")
    assert bool(calls) == pretrained  # frames are read only to pretrain
    assert len(curve) == (1 if pretrained else 0) and how
    assert all("seconds" not in row for row in curve)  # the curve edge is reproducible
    path = tmp_path / "b.pt"
    save_backbone(model, path)
    back = read_backbone(path)
    assert back.state_dict().keys() == model.state_dict().keys()
    for k, v in model.state_dict().items():  # the file gives back every weight bit for bit
        assert torch.equal(back.state_dict()[k], v), k
    x = frames[:3]
    want = extract_features(model, x, image_size=28, device="cpu", batch_size=64, pool="cls")
    # the read network is another computation (its kernels may be others): within rounding
    atol = vit_tiny_atol(want) if spec.arch == "vit_tiny" else resnet_tiny_atol(want)
    np.testing.assert_allclose(
        extract_features(back, x, image_size=28, device="cpu", batch_size=64, pool="cls"),
        want,
        rtol=0,
        atol=atol,
    )


def test_read_backbone_refuses_a_foreign_state_dict(tmp_path):
    path = tmp_path / "odd.pt"
    torch.save({"features.0.weight": torch.zeros(2)}, path)
    with pytest.raises(ValueError, match="neither a ViT.*nor a ResNet"):
        read_backbone(path)


# ----------------------------------------------------------------------------- config


def _config(**backbones):
    families = {
        "dinov2": {"vision": {"arch": "vit_tiny"}, "tactile": {"arch": "vit_tiny"}},
        "resnet": {
            "vision": {"arch": "resnet_tiny", "objective": "random"},
            "tactile": {"arch": "resnet_tiny", "objective": "random"},
        },
    }
    return {
        "features": {
            "pool": "cls",
            "backbones": {"vision": {"arch": "vit_tiny"}, "tactile": {"arch": "vit_tiny"}},
            "pretrain": {"epochs": 0},
            "mae": {"epochs": 1},
        },
        "probes": {
            "families": {
                "hardness": {"corpus": "p", "vision": "vit"},
                "mass": {"corpus": "c", "vision": "pixel"},
            }
        },
        "backbones": {"run": ["dinov2", "resnet"], "probes": ["hardness"], "families": families}
        | backbones,
    }


def test_family_settings_find_the_main_family_and_refuse_bad_names():
    cfg = _config()
    fam = FamilySettings.from_config(cfg)
    assert fam.is_main("dinov2", cfg["features"]) and fam.own(cfg["features"]) == ["resnet"]
    with pytest.raises(ConfigError, match="unknown family 'clip'"):
        FamilySettings.from_config(_config(run=["clip"]))
    with pytest.raises(ConfigError, match="'force' is not a probe family"):
        FamilySettings.from_config(_config(probes=["force"]))
    with pytest.raises(ConfigError, match="'mass' compares pixel V"):
        FamilySettings.from_config(_config(probes=["mass"]))


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        (BackboneSpec("resnet18", objective="dino"), "no in-workflow dino pretraining"),
        (BackboneSpec("resnet18", objective="mae"), "no in-workflow mae pretraining"),
        (BackboneSpec("vit_tiny", objective="mae"), "features.mae.epochs >= 1"),
        (BackboneSpec("vit_tiny", objective="simclr"), "simclr pretrains a ResNet"),
    ],
)
def test_backbones_the_workflow_cannot_make_are_refused(spec, needle):
    with pytest.raises(
        ValueError, match="objective must be one of 'dino', 'mae', 'simclr', 'random'"
    ):
        BackboneSpec("vit_tiny", objective="byol")
    with pytest.raises(ConfigError, match=needle):
        check_backbone(
            spec,
            where="backbones.families.x.vision",
            dino_epochs=0,
            mae_epochs=0,
            features_pool="cls",
        )
    check_backbone(
        BackboneSpec(
            spec.arch, checkpoint="w.pth", objective="mae" if spec.network == "vit" else "dino"
        ),
        where="x",
        dino_epochs=0,
        mae_epochs=0,
        features_pool="cls",
    )  # a checkpoint needs no pretraining


def test_the_stages_pool_is_refused_for_a_vit_from_either_key():
    kw = dict(where="features.backbones.tactile", dino_epochs=0, mae_epochs=0)
    with pytest.raises(ConfigError, match="tactile: pool stages .* the ViT vit_tiny"):
        check_backbone(BackboneSpec("vit_tiny", pool="stages"), features_pool="cls", **kw)
    with pytest.raises(ConfigError, match="tactile: features.pool stages"):
        check_backbone(BackboneSpec("vit_tiny"), features_pool="stages", **kw)
    # a ViT's own pool overrides features.pool; a ResNet reads stages either way
    check_backbone(BackboneSpec("vit_tiny", pool="cls"), features_pool="stages", **kw)
    check_backbone(
        BackboneSpec("resnet_tiny", objective="random", pool="stages"), features_pool="cls", **kw
    )
    check_backbone(BackboneSpec("resnet_tiny", objective="random"), features_pool="stages", **kw)


@pytest.mark.parametrize(
    ("spec", "dino_epochs", "pretrains"),
    [
        (BackboneSpec("vit_tiny"), 0, False),
        (BackboneSpec("vit_tiny"), 3, True),
        (BackboneSpec("vit_tiny", objective="mae"), 0, True),
        (BackboneSpec("resnet_tiny", objective="simclr"), 0, True),
        (BackboneSpec("resnet_tiny", objective="random"), 5, False),
        (BackboneSpec("vit_tiny", checkpoint="w.pth"), 5, False),
    ],
)
def test_a_backbone_pretrains_only_where_it_learns_from_frames(spec, dino_epochs, pretrains):
    assert spec.pretrains(dino_epochs) is pretrains
    assert ("random init" in spec.label(dino_epochs)) is (not pretrains and not spec.checkpoint)


def test_pretraining_corpora_are_one_name_or_a_list_in_order():
    assert pretraining_corpora({"corpus": "sim_paired"}) == ("sim_paired",)
    assert pretraining_corpora({"corpus": ["b", "a"]}) == ("b", "a")


def test_feature_settings_take_each_backbones_own_pool():
    features = validated()["features"]
    features = {
        **features,
        "pool": "cls",
        "backbones": {
            "vision": {"arch": "resnet_tiny", "objective": "simclr", "pool": "stages"},
            "tactile": {"arch": "vit_tiny"},
        },
    }
    assert FeatureSettings.for_backbone(features, "vision").pool == "stages"
    assert FeatureSettings.for_backbone(features, "tactile").pool == "cls"
    assert FeatureSettings.from_config(features).pool == "cls"


# ----------------------------------------------------------------------------- probes, report


def _world(kind, carries, n_train=90, n_test=60, seed=0):
    rng = np.random.default_rng(seed)
    n = n_train + n_test
    z = rng.standard_normal(n)
    v = rng.standard_normal((n, 10))
    t = rng.standard_normal((n, 6))
    if carries:
        t[:, :2] += 2.0 * z[:, None]
    y = (
        z + 0.3 * rng.standard_normal(n)
        if kind == "ridge"
        else np.where(z > 0, "hard", "soft").astype(object)
    )
    rows = synthetic_family_rows(kind, y, n_train)
    return rows, (v[:n_train], v[n_train:]), (t[:n_train], t[n_train:])


#: the embedded default's probe settings (what rule family_probe passes on), at fewer resamples
PROBES_CFG = {k: v for k, v in validated()["probes"].items() if k not in ("families", "seeds")} | {
    "bootstrap": 300
}


@pytest.mark.parametrize("kind", ["ridge", "logistic"])
def test_family_rows_find_touch_where_it_carries_the_label_and_not_where_it_does_not(kind):
    out = {}
    for carries in (True, False):
        rows, v, t = _world(kind, carries)
        out[carries] = backbone_family_rows(
            "resnet",
            "p",
            rows,
            vision=v,
            tactile=t,
            probes_cfg=PROBES_CFG,
            kind=kind,
            protocols=["raw", "mlp2"],
            seed=42,
            labels={"vision": "resnet_tiny (random init)", "tactile": "resnet_tiny (random init)"},
            null_corpus=not carries,
        )
    frame = out[True]
    assert list(frame.columns) == list(FAMILY_COLUMNS)
    assert list(frame["protocol"]) == ["raw", "mlp2"] and (frame["status"] == "ok").all()
    assert (frame["ci_low"] > 0).all()  # touch carries z: V+T beats V under both probes
    assert (out[False]["ci_low"] <= 0).all()  # touch is noise: no interval above 0
    assert (frame["n_resamples"] == 300).all()


def test_report_sentences_say_where_the_direction_holds_and_flag_a_null_gain():
    def row(family, probe, protocol, delta, lo, hi, null):
        return {
            "row_id": f"{family}|{probe}|{protocol}",
            "family": family,
            "vision_backbone": "v",
            "tactile_backbone": "t",
            "probe": probe,
            "corpus": "null" if null else "paired",
            "null_corpus": null,
            "target": "y",
            "metric": "r2",
            "protocol": protocol,
            "n_train": 10,
            "n_test": 5,
            "dim_v": 2,
            "dim_t": 2,
            "status": "ok",
            "v_score": 0.1,
            "vt_score": 0.1 + delta,
            "delta": delta,
            "ci_low": lo,
            "ci_high": hi,
            "p_gt0": 0.5,
            "n_resamples": 100,
            "notes": "",
        }

    rows = pd.DataFrame(
        [
            row("a", "force", "raw", 0.2, 0.1, 0.3, False),
            row("a", "force_null", "raw", 0.0, -0.1, 0.1, True),
            row("b", "force", "raw", -0.1, -0.2, 0.0, False),
            row("b", "force_null", "raw", 0.2, 0.1, 0.3, True),
        ]
    )
    weak = row("a", "force", "mlp2", 0.9, 0.6, 1.2, False) | {"v_score": -0.3}
    rows = pd.concat([rows, pd.DataFrame([weak])], ignore_index=True)
    a, b = family_sentences(rows, ["a", "b"])
    assert "The 2-layer probe's V scores below the linear V on force" in a
    assert "below the linear V" not in b
    assert a.startswith("a (V v, T t): The V+T direction holds.")
    assert "CI above 0 on 1 of 1" in a and "null corpus CI above 0 on 0 of 1" in a
    assert "does not hold" in b and "UNEXPECTED" in b and "(force_null, linear)" in b
    table = family_table(rows, ["b", "a"])
    assert list(table["family"]) == ["b", "b", "a", "a", "a"]  # configured order
    assert table["probe"].iloc[1] == "force_null (null, null)"  # null rows after the real ones
    assert list(table["probe kind"].iloc[2:4]) == ["linear", "2-layer MLP"]


def test_main_family_rows_are_the_probe_stage_headline_rows():
    def probe_row(**kw):
        base = {
            "input": "raw",
            "fusion": "concat",
            "t_variant": "clip128",
            "control": "none",
            "corpus": "paired",
            "null_corpus": False,
            "target": "hardness",
            "metric": "accuracy",
            "n_train": 40,
            "n_test": 20,
            "dim_v": 192,
            "dim_vt": 384,
            "status": "ok",
            "v_score": 0.5,
            "vt_score": 0.7,
            "delta": 0.2,
            "ci_low": 0.1,
            "ci_high": 0.3,
            "p_gt0": 1.0,
            "n_resamples": 100,
        }
        return base | kw

    edge = pd.DataFrame(
        [
            probe_row(),
            probe_row(input="aligned", delta=9.0),
            probe_row(fusion="mean", delta=9.0),
            probe_row(t_variant="none", delta=9.0),
            probe_row(control="tactile_permutation", delta=9.0),
        ]
    )
    got = rows_from_probes(
        {("hardness", "raw"): edge},
        family="dinov2",
        heads_variant="clip128",
        labels={"vision": "v", "tactile": "t"},
    )
    assert list(got.columns) == list(FAMILY_COLUMNS) and len(got) == 1
    r = got.iloc[0]
    assert (r["row_id"], r["delta"], r["dim_t"]) == ("dinov2|hardness|raw", 0.2, 192)
    with pytest.raises(ValueError, match="'hardness', protocol 'mlp2': 0 headline rows"):
        rows_from_probes(
            {("hardness", "mlp2"): edge.iloc[1:]},
            family="dinov2",
            heads_variant="clip128",
            labels={"vision": "v", "tactile": "t"},
        )


def test_findings_row_per_other_family_with_the_null_corpus_beside():
    from tacgen_lib.report.findings import FINDINGS_COLUMNS, backbone_findings

    def row(family, probe, protocol, delta, lo, null):
        return {
            "family": family,
            "vision_backbone": "v",
            "tactile_backbone": "t",
            "probe": probe,
            "null_corpus": null,
            "protocol": protocol,
            "status": "ok",
            "delta": delta,
            "ci_low": lo,
            "ci_high": lo + 0.2,
        }

    summary = pd.DataFrame(
        [
            row("dinov2", "force", "raw", 0.5, 0.4, False),
            row("resnet", "force", "raw", 0.3, 0.2, False),
            row("resnet", "force", "mlp2", -0.3, -0.5, False),  # not the linear probe
            row("resnet", "force_null", "raw", 0.2, 0.1, True),
        ]
    )
    got, decided = backbone_findings(summary, main=["dinov2"])
    by_id = {d["decision_id"]: d["decision"] for d in decided}
    assert by_id == {
        "backbones|resnet|direction": "holds",
        "backbones|resnet|null_gains": "force_null",
    }
    assert list(got.columns) == FINDINGS_COLUMNS and list(got["evidence"]) == ["backbone families"]
    r = got.iloc[0]
    assert "resnet" in r["question"] and r["result"] == "V+T − V: force +0.300 [+0.200, +0.400]"
    assert r["control"].startswith("null corpus V+T − V: force_null +0.200")
    assert r["verdict"].startswith("The V+T direction holds") and "UNEXPECTED" in r["verdict"]
    assert backbone_findings(summary[summary["family"] == "dinov2"], main=["dinov2"]).rows.empty
