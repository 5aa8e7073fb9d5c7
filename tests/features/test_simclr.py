"""SimCLR pretraining of a ResNet (tacgen_lib.features.simclr): reproducible, minimising its
objective, greyscale views equal to a float64 reference, and the inputs it refuses."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from pretrain_checks import assert_loss_falls, assert_same_backbone

from tacgen_lib.estimate.counts import pretraining
from tacgen_lib.features.extract import extract_features
from tacgen_lib.features.resnet import random_resnet
from tacgen_lib.features.settings import SimclrSettings
from tacgen_lib.features.simclr import grey_views, pretrain_simclr


def _frames(n=32, size=32, seed=0):
    """Half checkered, half plain frames of random colours: two textures to tell apart."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size]
    checker = ((yy // 4 + xx // 4) % 2).astype(np.float64)
    out = np.empty((n, size, size, 3), dtype=np.uint8)
    for i in range(n):
        colour = rng.uniform(60, 230, 3)
        shade = 1.0 - 0.6 * checker if i % 2 else np.ones((size, size))
        out[i] = np.clip(shade[..., None] * colour, 0, 255).astype(np.uint8)
    return out


def test_pretrain_simclr_is_bit_identical_when_run_twice_and_its_loss_falls():
    frames = _frames()
    settings = SimclrSettings.tiny(epochs=6, batch_size=16, lr=3e-3)
    torch.set_num_threads(1)
    one = pretrain_simclr(
        frames, settings, arch="resnet_tiny", image_size=32, device="cpu", pool="cls"
    )
    two = pretrain_simclr(
        frames, settings, arch="resnet_tiny", image_size=32, device="cpu", pool="cls"
    )
    assert_same_backbone(one, two)
    assert_loss_falls(one.curve, epochs=6)
    model = one.backbone()
    random = random_resnet("resnet_tiny", seed=settings.seed)
    x = frames[:4]
    learnt = extract_features(model, x, image_size=32, device="cpu", batch_size=64, pool="cls")
    assert learnt.shape == (4, 128) and np.isfinite(learnt).all()
    assert not np.array_equal(
        learnt, extract_features(random, x, image_size=32, device="cpu", batch_size=64, pool="cls")
    )


def test_another_seed_gives_another_backbone():
    frames = _frames(n=16)
    a = pretrain_simclr(
        frames, SimclrSettings.tiny(), arch="resnet_tiny", image_size=32, device="cpu", pool="cls"
    )
    b = pretrain_simclr(
        frames,
        SimclrSettings.tiny(seed=1),
        arch="resnet_tiny",
        image_size=32,
        device="cpu",
        pool="cls",
    )
    assert not torch.equal(a.backbone_state["conv1.weight"], b.backbone_state["conv1.weight"])


@pytest.mark.parametrize("p", [0.0, 0.5, 1.0])
def test_grey_views_equal_a_float64_reference(p):
    x = torch.rand(64, 3, 5, 5, generator=torch.Generator().manual_seed(3))
    got = grey_views(x, p, torch.Generator().manual_seed(7))
    u = torch.rand(64, 1, 1, 1, generator=torch.Generator().manual_seed(7))
    xd = x.double()
    want = torch.where(u < p, xd.mean(dim=1, keepdim=True).expand_as(xd), xd)
    torch.testing.assert_close(got.double(), want, rtol=1e-6, atol=1e-7)
    greyed = (u.flatten() < p).sum().item()
    assert greyed == {0.0: 0, 1.0: 64}.get(p, greyed)
    if p == 0.0:
        assert torch.equal(got, x)


def test_pretrain_simclr_refuses_a_vit_foreign_frames_and_a_single_frame():
    frames = _frames(n=4)
    with pytest.raises(ValueError, match="'vit_tiny' is not a ResNet"):
        pretrain_simclr(
            frames, SimclrSettings.tiny(), arch="vit_tiny", image_size=28, device="cpu", pool="cls"
        )
    with pytest.raises(ValueError, match="expected uint8 frames"):
        pretrain_simclr(
            frames.astype(np.float32),
            SimclrSettings.tiny(),
            arch="resnet_tiny",
            image_size=32,
            device="cpu",
            pool="cls",
        )
    with pytest.raises(ValueError, match="at least 2 frames"):
        pretrain_simclr(
            frames[:1],
            SimclrSettings.tiny(),
            arch="resnet_tiny",
            image_size=32,
            device="cpu",
            pool="cls",
        )


def test_settings_are_the_schema_s_and_the_estimate_prices_their_epochs():
    s = SimclrSettings.from_config({"epochs": 7})
    assert s.epochs == 7 and s.tau == SimclrSettings().tau
    with pytest.raises(ValueError, match="grey"):
        SimclrSettings(grey=1.5)
    config = {"features": {"simclr": {"epochs": 7}, "pretrain": {"epochs": 0}}}
    spec = {"arch": "resnet_tiny", "objective": "simclr", "checkpoint": None}
    assert pretraining(config, spec) == ("simclr", 7)


def test_the_projection_reads_the_stage_statistics_for_the_stages_pool(monkeypatch):
    """With pool "stages" the contrastive loss is computed on what the features will read
    (ResNet.stage_statistics), with any other pool on the last stage's average; the two
    pretrainings of one seed make different backbones."""
    from tacgen_lib.features.resnet import ResNet

    calls = []
    real = ResNet.stage_statistics

    def counted(self, x):
        calls.append(x.shape[0])
        return real(self, x)

    monkeypatch.setattr(ResNet, "stage_statistics", counted)
    frames = np.random.default_rng(0).integers(0, 256, size=(16, 40, 40, 3), dtype=np.uint8)
    settings = SimclrSettings.tiny()
    cls = pretrain_simclr(
        frames, settings, arch="resnet_tiny", image_size=32, device="cpu", pool="cls"
    )
    assert calls == []
    stages = pretrain_simclr(
        frames, settings, arch="resnet_tiny", image_size=32, pool="stages", device="cpu"
    )
    steps = 16 // settings.batch_size
    assert calls == [settings.batch_size] * (2 * steps * settings.epochs)  # both views, each step
    assert any(
        not torch.equal(cls.backbone_state[k], stages.backbone_state[k]) for k in cls.backbone_state
    )
