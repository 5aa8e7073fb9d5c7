"""Frozen-feature extraction (CLS / mean patch) and the pixel-V baseline."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from tacgen_lib.features.extract import (
    IMAGENET_MEAN,
    IMAGENET_STD,
    extract_features,
    imagenet_normalise,
    pixel_features,
    to_unit_tensor,
)
from tacgen_lib.features.vit import build_vit


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return build_vit("vit_tiny", img_size=56)


def _images(n: int, h: int = 40, w: int = 60, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (n, h, w, 3), dtype=np.uint8)


def test_imagenet_normalise_matches_float64_reference():
    x = torch.rand(2, 3, 5, 5, dtype=torch.float64)
    ref = (x.numpy() - np.array(IMAGENET_MEAN)[None, :, None, None]) / np.array(IMAGENET_STD)[
        None, :, None, None
    ]
    np.testing.assert_allclose(imagenet_normalise(x).numpy(), ref, rtol=1e-14)


def test_to_unit_tensor_scales_and_resizes():
    imgs = _images(2, 28, 28)
    x = to_unit_tensor(imgs, 28)  # no resize: exact /255
    np.testing.assert_array_equal(x.numpy(), imgs.transpose(0, 3, 1, 2).astype(np.float32) / 255)
    const = np.full((1, 37, 53, 3), 200, np.uint8)
    y = to_unit_tensor(const, 56)
    assert y.shape == (1, 3, 56, 56)
    torch.testing.assert_close(y, torch.full_like(y, 200 / 255))


@pytest.mark.parametrize("pool", ["cls", "mean_patch"])
def test_extract_features_matches_manual_forward(model, pool):
    imgs = _images(5)
    got = extract_features(model, imgs, image_size=56, batch_size=2, pool=pool, device="cpu")
    assert got.dtype == np.float32 and got.shape == (5, model.embed_dim)
    with torch.inference_mode():
        out = model.eval().forward_features(imagenet_normalise(to_unit_tensor(imgs, 56)))
    ref = out["x_norm_clstoken"] if pool == "cls" else out["x_norm_patchtokens"].mean(1)
    # batches of 2 against one of 5: another GEMM shape. float32 unit roundoff 6e-8; sums of
    # <= 768 terms reordered in ~48 products (12 blocks), each behind a LayerNorm: ~sqrt(768)
    # x 6e-8 ~ 2e-6 per product, random-walking to ~1e-5 of the O(1) features -> rtol = atol
    # = 1e-5 (1.7e-6 seen with MKL_CBWR=COMPATIBLE; 0 with this CPU's default kernels)
    np.testing.assert_allclose(got, ref.numpy(), rtol=1e-5, atol=1e-5)


def test_extract_features_is_bytewise_deterministic_and_restores_mode(model):
    imgs = _images(7, seed=1)
    model.train()
    a = extract_features(model, imgs, image_size=56, batch_size=3, pool="cls", device="cpu")
    assert model.training
    b = extract_features(model, imgs, image_size=56, batch_size=3, pool="cls", device="cpu")
    assert a.tobytes() == b.tobytes()
    # other batch sizes agree numerically (GEMM blocking may differ in the last bits): as in
    # test_extract_features_matches_manual_forward, ~1e-5 of the O(1) features; rtol 1e-4
    # for the CLS token's larger entries (up to 3.3)
    c = extract_features(model, imgs, image_size=56, batch_size=7, pool="cls", device="cpu")
    np.testing.assert_allclose(a, c, rtol=1e-4, atol=1e-5)


def test_extract_features_other_image_sizes_interpolate_pos_embed(model):
    feats = extract_features(
        model, _images(2), image_size=112, batch_size=2, pool="mean_patch", device="cpu"
    )
    assert feats.shape == (2, model.embed_dim) and np.isfinite(feats).all()


def test_extract_features_errors(model):
    with pytest.raises(TypeError, match="uint8"):
        extract_features(
            model,
            _images(2).astype(np.float32),
            image_size=56,
            device="cpu",
            batch_size=64,
            pool="cls",
        )
    with pytest.raises(ValueError, match=r"\(N, H, W, 3\)"):
        extract_features(
            model, _images(2)[..., 0], image_size=56, device="cpu", batch_size=64, pool="cls"
        )
    with pytest.raises(ValueError, match="pool must be"):
        extract_features(model, _images(2), image_size=56, pool="max", device="cpu", batch_size=64)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="not a multiple of the patch size"):
        extract_features(model, _images(2), image_size=50, device="cpu", batch_size=64, pool="cls")


def test_pixel_features_are_area_means_in_unit_range():
    imgs = _images(3, 32, 48, seed=2)
    got = pixel_features(imgs, size=(16, 8))
    assert got.dtype == np.float32 and got.shape == (3, 16 * 8 * 3)
    # integer factors: INTER_AREA is the block mean (2 x 6 blocks), rounded to uint8
    ref = imgs.astype(np.float64).reshape(3, 16, 2, 8, 6, 3).mean(axis=(2, 4)) / 255
    np.testing.assert_allclose(got.reshape(3, 16, 8, 3), ref, atol=0.5 / 255 + 1e-7)
    assert got.min() >= 0 and got.max() <= 1


def test_pixel_features_matches_cv2_for_non_integer_factor():
    imgs = _images(2, 37, 53, seed=3)
    got = pixel_features(imgs, size=(16, 16))
    for i in range(2):
        ref = cv2.resize(imgs[i], (16, 16), interpolation=cv2.INTER_AREA).astype(np.float32) / 255
        np.testing.assert_array_equal(got[i], ref.reshape(-1))
    with pytest.raises(ValueError, match="positive"):
        pixel_features(imgs, size=(0, 4))
