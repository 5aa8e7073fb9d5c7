"""Background subtraction (tactile_proc) and its ablation variants."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis.extra.numpy import arrays

from tacgen_lib.preprocess.background import (
    VARIANTS,
    background_subtract,
    clahe_proc,
    histogram_match,
    residual_proc,
    tactile_proc,
)

frames = arrays(np.uint8, (6, 7, 3))


def _frame(seed: int, shape=(24, 32, 3)) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)


def test_tactile_proc_frame_equals_background_is_128():
    f = _frame(0)
    out = tactile_proc(f, f)
    assert out.dtype == np.uint8 and out.shape == f.shape
    assert np.all(out == 128)


def test_tactile_proc_extremes_clip_without_wraparound():
    zeros = np.zeros((4, 5, 3), np.uint8)
    full = np.full((4, 5, 3), 255, np.uint8)
    assert np.all(tactile_proc(zeros, full) == 0)  # 0 - 255 + 128 = -127 -> 0
    assert np.all(tactile_proc(full, zeros) == 255)  # 255 - 0 + 128 = 383 -> 255


@settings(max_examples=50, deadline=None)
@given(frames, frames)
def test_tactile_proc_matches_int64_reference(t, b):
    ref = np.clip(t.astype(np.int64) - b.astype(np.int64) + 128, 0, 255)
    np.testing.assert_array_equal(tactile_proc(t, b), ref)


@settings(max_examples=50, deadline=None)
@given(frames, frames)
def test_residual_is_fixed_affine_map_without_clipping(t, b):
    r = t.astype(np.int64) - b.astype(np.int64)
    out = residual_proc(t, b)
    np.testing.assert_array_equal(out, np.floor((r + 256) / 2))
    # monotone in the residual and never saturating except at the ends of [-255, 255]
    assert out.min() >= 0 and out.max() <= 255


def test_residual_extremes_and_zero():
    zeros = np.zeros((2, 2, 3), np.uint8)
    full = np.full((2, 2, 3), 255, np.uint8)
    assert np.all(residual_proc(zeros, full) == 0)
    assert np.all(residual_proc(full, zeros) == 255)
    assert np.all(residual_proc(full, full) == 128)


@pytest.mark.parametrize("variant", ["clip128", "histmatch", "residual"])
def test_subtracting_variants_give_128_when_frame_equals_background(variant):
    f = _frame(1)
    assert np.all(background_subtract(f, f, variant) == 128)


def test_histogram_match_identity_and_monotone_lut():
    f = _frame(2)
    np.testing.assert_array_equal(histogram_match(f, f), f)
    # a global brightness shift of the background is undone by matching it to the frame
    frame = np.clip(_frame(3).astype(np.int16) // 2 + 60, 0, 255).astype(np.uint8)
    bg = (frame.astype(np.int16) - 40).astype(np.uint8)
    np.testing.assert_array_equal(histogram_match(bg, frame), frame)
    out = background_subtract(frame, bg, "histmatch")
    assert np.all(out == 128)
    # plain clip128 sees the shift as signal
    assert np.all(background_subtract(frame, bg, "clip128") == 168)


def test_histogram_match_matches_quantile_reference():
    rng = np.random.default_rng(4)
    src = rng.integers(0, 256, (20, 20, 3), dtype=np.uint8)
    tmpl = rng.integers(50, 120, (10, 30, 3), dtype=np.uint8)
    out = histogram_match(src, tmpl)
    for c in range(3):
        s, t = src[:, :, c].ravel(), tmpl[:, :, c].ravel()
        sv, sc = np.unique(s, return_counts=True)
        tv, tc = np.unique(t, return_counts=True)
        ref_map = np.interp(np.cumsum(sc) / s.size, np.cumsum(tc) / t.size, tv)
        ref = np.rint(ref_map[np.searchsorted(sv, s)]).reshape(20, 20)
        np.testing.assert_array_equal(out[:, :, c], ref)
    assert out.min() >= 50 and out.max() <= 119


def test_clahe_matches_opencv_on_lab_l_channel_and_ignores_background():
    f = _frame(5, (64, 64, 3))
    lab = cv2.cvtColor(f, cv2.COLOR_RGB2LAB)
    lab[:, :, 0] = cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(lab[:, :, 0])
    ref = cv2.cvtColor(lab, cv2.COLOR_LAB2RGB)
    np.testing.assert_array_equal(clahe_proc(f), ref)
    np.testing.assert_array_equal(background_subtract(f, _frame(6, (64, 64, 3)), "clahe"), ref)


def test_none_returns_a_copy_of_the_raw_frame():
    f = _frame(7)
    out = background_subtract(f, _frame(8), "none")
    np.testing.assert_array_equal(out, f)
    assert out is not f


@pytest.mark.parametrize("variant", VARIANTS)
def test_every_variant_returns_uint8_rgb_of_the_input_shape(variant):
    out = background_subtract(_frame(9), _frame(10), variant)
    assert out.dtype == np.uint8 and out.shape == (24, 32, 3)


def test_unknown_variant_lists_valid_names():
    with pytest.raises(ValueError, match="clip128.*histmatch.*residual.*clahe.*none"):
        background_subtract(_frame(0), _frame(0), "clip")


@pytest.mark.parametrize("variant", VARIANTS)
def test_shape_mismatch_is_refused(variant):
    with pytest.raises(ValueError, match="differ in shape"):
        background_subtract(_frame(0, (24, 32, 3)), _frame(0, (32, 24, 3)), variant)


def test_dtype_and_layout_errors():
    f = _frame(0)
    with pytest.raises(TypeError, match="uint8"):
        tactile_proc(f.astype(np.float32), f)
    with pytest.raises(TypeError, match="uint8"):
        tactile_proc(f, f.astype(np.int16))
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        tactile_proc(f[:, :, 0], f[:, :, 0])
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        tactile_proc(np.zeros((4, 4, 4), np.uint8), np.zeros((4, 4, 4), np.uint8))


def test_a_sensor_frame_of_the_wrong_size_names_the_sample_and_its_sensor():
    """A second sensor's frame (another frame size) read against the first sensor's background:
    the job stops naming the edge, the sample_id and the sensor, before anything is written."""
    import pandas as pd

    from tacgen_lib.io.images import encode_png
    from tacgen_lib.preprocess.frames import subtract_backgrounds

    samples = pd.DataFrame(
        {
            "sample_id": ["t-000000", "t-000001"],
            "sensor_id": ["digit-0", "digit-0"],
            "tactile": [encode_png(_frame(1)), encode_png(_frame(2, (48, 64, 3)))],
        }
    )
    backgrounds = {"digit-0": _frame(3)}
    with pytest.raises(
        ValueError,
        match=r"results/x\.parquet: sample_id 't-000001' column 'tactile' \(sensor 'digit-0'\): "
        ".*differ in shape",
    ):
        subtract_backgrounds(samples, backgrounds, "clip128", where="results/x.parquet")
