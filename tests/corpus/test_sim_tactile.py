"""Tactile frames: ray-cast height field, gel compression, three-light shading (tacgen_lib.corpus.sim)."""

import numpy as np
import pytest
from sim_scenes import gel_heights

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
    elevation = np.deg2rad(optics.light_elevation)
    ce, se = np.cos(elevation), np.sin(elevation)
    frame = background.astype(np.float64)
    for c, az in enumerate(np.deg2rad(optics.light_azimuths)):
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
    got = gel_heights(rt, OPTICS)
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


#: a GelSight-like sensor's illumination (config/scenes.yaml, gelsight_press): other azimuths
#: per colour channel and a lower elevation
OTHER_LIGHTS = {"light_azimuths": (30.0, 150.0, 270.0), "light_elevation": 25.0}


def test_default_lights_are_the_digit_like_constants():
    assert np.array_equal(np.deg2rad(OPTICS.light_azimuths), tactile.LIGHT_AZIMUTHS)
    assert np.deg2rad(OPTICS.light_elevation) == tactile.LIGHT_ELEVATION


def test_declared_lights_match_the_float64_reference():
    from dataclasses import replace

    optics = replace(OPTICS, **OTHER_LIGHTS)
    bg = np.full((120, 160, 3), 128, dtype=np.uint8)
    height, _ = sphere_cap(0.0015)
    got = tactile.tactile_shading(height, bg, optics)
    want, _ = shading_reference(height, bg, optics)
    assert np.abs(got.astype(int) - want.astype(int)).max() <= 1  # float32 vs float64 rounding
    # other lights shade the same imprint otherwise: the sensors differ where it is
    default = tactile.tactile_shading(height, bg, OPTICS)
    assert np.abs(got.astype(int) - default.astype(int)).max() > 10


def test_lights_rotated_by_a_third_permute_the_colour_channels():
    """On a grey background, lights rotated by 120 degrees shade channel c as the default
    lights shade channel c + 1: the same operations on the same numbers."""
    from dataclasses import replace

    rotated = replace(OPTICS, light_azimuths=(210.0, 330.0, 90.0))
    bg = np.full((120, 160, 3), 128, dtype=np.uint8)
    height, _ = sphere_cap(0.0015)
    a = tactile.tactile_shading(height, bg, OPTICS)
    b = tactile.tactile_shading(height, bg, rotated)
    np.testing.assert_array_equal(b, a[..., [1, 2, 0]])


def test_marker_grid_spacing_and_radius_are_the_declared_ones():
    dense = tactile.marker_pattern((60, 80), spacing=9, radius=1.2)
    assert dense[0, 0] == dense[9, 18] == 1.0  # dot centres every 9 pixels
    assert dense[1, 0] == pytest.approx(np.exp(-1.0 / (2 * 1.2**2)), rel=1e-6)  # its radius
    # 9-pixel period in both directions
    np.testing.assert_allclose(dense[:-9], dense[9:], atol=1e-6)
    np.testing.assert_allclose(dense[:, :-9], dense[:, 9:], atol=1e-6)


@pytest.mark.parametrize(
    ("gel", "words"),
    [
        ({"light_azimuths": [0, 120]}, "3 azimuths"),
        ({"light_elevation": 95}, "light_elevation"),
        ({"marker_spacing": 4, "marker_radius": 5}, "marker grid"),
    ],
)
def test_bad_sensor_optics_name_scene_and_key(gel, words):
    decl = {"kind": "press", "effects": ["tactile"], "gel": gel}
    with pytest.raises(ValueError, match=words):
        validate_scene("odd_sensor", decl)
