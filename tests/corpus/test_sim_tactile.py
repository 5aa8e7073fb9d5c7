"""Tactile frames: ray-cast height field, gel compression, three-light shading (tacgen_lib.corpus.sim)."""

import numpy as np
import pytest

from tacgen_lib.corpus.sim import physics, tactile
from tacgen_lib.corpus.sim.scenes import compile_scene, validate_scene

OPTICS = tactile.GelOptics((0.045, 0.06), (120, 160), 0.05, 0.002, 0.0006)


def shading_reference(height, background, optics, noise_rng=None):
    """Whole-frame float64 version of tactile_shading (no ROI, no float32, plain numpy)."""
    import cv2

    hc = optics.saturation * np.tanh(height / optics.saturation)
    sigma = optics.smoothing / optics.pixel_size
    k = 2 * int(np.ceil(3 * sigma)) + 1
    hc = cv2.GaussianBlur(hc, (k, k), sigma, sigmaY=sigma, borderType=cv2.BORDER_REPLICATE)
    pad = np.pad(hc, 1, mode="edge")
    gx = (pad[1:-1, 2:] - pad[1:-1, :-2]) / (2 * optics.pixel_size)
    gy = -(pad[2:, 1:-1] - pad[:-2, 1:-1]) / (2 * optics.pixel_size)
    inv = 1 / np.sqrt(1 + gx**2 + gy**2)
    ce, se = np.cos(tactile.LIGHT_ELEVATION), np.sin(tactile.LIGHT_ELEVATION)
    frame = background.astype(np.float64)
    for c, az in enumerate(tactile.LIGHT_AZIMUTHS):
        lam = (-ce * np.cos(az) * gx - ce * np.sin(az) * gy + se) * inv
        frame[..., c] += tactile.SLOPE_GAIN * (np.maximum(lam, 0) - se)
        frame[..., c] += tactile.DEPTH_GAIN / optics.saturation * hc
    if noise_rng is not None:
        frame += tactile.sensor_noise(noise_rng, frame.shape)
    return np.clip(np.rint(frame), 0, 255).astype(np.uint8), frame


def sphere_cap(depth_m, radius=0.01, centre=(0.004, -0.003)):
    """Analytic indentation of a sphere pressed depth_m below the rest plane, per pixel ray."""
    d = tactile.ray_directions(OPTICS)
    pinhole = np.array([0.0, 0.0, -OPTICS.camera_distance])
    c = np.array([centre[0], centre[1], radius - depth_m])
    oc = pinhole - c
    b = d @ oc
    disc = b**2 - (oc @ oc - radius**2)
    t = -b - np.sqrt(np.maximum(disc, 0))
    z = pinhole[2] + t * d[..., 2]
    return np.where(disc > 0, np.maximum(-z, 0), 0.0), c


def test_rays_match_analytic_sphere_cap():
    scene = validate_scene("t", {"effects": ["tactile"], "objects": {"shapes": ["sphere"]}})
    rt = physics.SceneRuntime(scene, compile_scene(scene))
    physics.apply_object(rt, physics.ObjectPhysics("sphere", 0.02, 1000, 1e4, 0.5))
    expected, centre = sphere_cap(0.0015)
    rt.data.qpos[rt.object_qpos : rt.object_qpos + 3] = centre
    import mujoco

    mujoco.mj_forward(rt.model, rt.data)
    got = tactile.height_field_rays(
        rt.model,
        rt.data,
        rt.active_geom,
        np.zeros(3),
        np.eye(3).ravel(),
        OPTICS,
        tactile.ray_directions(OPTICS),
    )
    assert got.max() == pytest.approx(0.0015, abs=2e-5)
    np.testing.assert_allclose(got, expected, atol=1e-9)


def test_no_contact_is_exactly_background_plus_noise():
    bg = tactile.sensor_background([3, 1, 0xB6], (120, 160))
    got = tactile.tactile_shading(np.zeros((120, 160)), bg, OPTICS, noise=np.random.default_rng(5))
    noise = tactile.sensor_noise(np.random.default_rng(5), (120, 160, 3))
    want = np.clip(np.rint(bg.astype(np.float32) + noise), 0, 255).astype(np.uint8)
    np.testing.assert_array_equal(got, want)
    assert np.array_equal(tactile.tactile_shading(np.zeros((120, 160)), bg, OPTICS), bg)


@pytest.mark.parametrize("depth", [0.0003, 0.0015, 0.05, 1.0])
def test_shading_matches_float64_reference_and_saturates(depth):
    bright = np.full((120, 160, 3), 250, dtype=np.uint8)  # clipping must not wrap around
    height, _ = sphere_cap(min(depth, 0.0099))
    height = height * (depth / max(height.max(), 1e-12))  # arbitrary depth, even 1 m
    got = tactile.tactile_shading(height, bright, OPTICS)
    want, raw = shading_reference(height, bright, OPTICS)
    assert got.dtype == np.uint8 and np.isfinite(raw).all()
    assert np.abs(got.astype(int) - want.astype(int)).max() <= 1  # float32 vs float64 rounding
    assert np.all(got[raw > 255.5] == 255) and np.all(got[raw < -0.5] == 0)
    assert tactile.gel_compression(np.array(depth), 0.002) <= 0.002


def test_gel_compression_is_tanh_like():
    h = np.linspace(0, 0.02, 200)
    c = tactile.gel_compression(h, 0.002)
    assert np.all(np.diff(c) > 0) and c.max() < 0.002
    np.testing.assert_allclose(tactile.gel_compression(np.array([1e-6]), 0.002), 1e-6, rtol=1e-6)


def test_backgrounds_are_seeded_smooth_and_distinct():
    a = tactile.sensor_background([7, 0, 0xB6], (120, 160))
    assert np.array_equal(a, tactile.sensor_background([7, 0, 0xB6], (120, 160)))
    b = tactile.sensor_background([7, 1, 0xB6], (120, 160))
    assert np.abs(a.astype(int) - b.astype(int)).mean() > 2
    assert np.abs(np.diff(a.astype(int), axis=1)).mean() < 1.0  # smooth: no pixel noise


def test_markers_move_with_indentation():
    bg = np.full((120, 160, 3), 128, dtype=np.uint8)
    markers = tactile.marker_pattern((120, 160))
    flat = tactile.tactile_shading(np.zeros((120, 160)), bg, OPTICS, markers=markers)
    height, _ = sphere_cap(0.0015)
    pressed = tactile.tactile_shading(height, bg, OPTICS, markers=markers)
    assert flat.min() < 80  # dark dots exist
    far = (slice(0, 10), slice(0, 10))
    assert np.array_equal(flat[far], pressed[far])
    assert not np.array_equal(flat, pressed)
