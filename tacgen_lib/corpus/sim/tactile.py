"""DIGIT-like tactile frames: gel indentation height field -> three-light shading -> frame.

Pipeline (GelSight/TACTO style):

1. `height_field_rays`: the object's surface below the gel's rest plane, measured by casting
   one MuJoCo ray per pixel (`mj_multiRay`) from the sensor's pinhole behind the gel. Rays are
   cast only inside the image box that can see the object's bounding sphere below the rest
   plane; every other pixel is exactly 0. (`height_field_depth` is the offscreen depth-render
   alternative, kept for the benchmark that chose rays; see benchmarks/bench_sim.py.)
2. `gel_compression`: the gel takes at most `saturation` metres: h -> s * tanh(h / s).
3. `tactile_shading`: membrane smoothing (Gaussian, `smoothing` metres), surface normals from
   the height-field gradient, three coloured lights (red, green, blue at 120 degrees, GelSight
   layout) with Lambertian response minus the flat-gel response, plus a small depth term
   (thinned gel transmits more light), optional markers, added to the sensor's background,
   plus seeded noise; computed in float32, clipped to [0, 255], rounded -> uint8.

With no contact (h == 0) the shading term is exactly zero, so the frame is exactly
background + noise (and markers, when declared).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import mujoco
import numpy as np
from scipy.special import ndtri

__all__ = [
    "GelOptics",
    "sensor_background",
    "ray_directions",
    "height_field_rays",
    "height_field_depth",
    "gel_compression",
    "marker_pattern",
    "sensor_noise",
    "tactile_shading",
]

#: the DIGIT-like sensor's lights in degrees (GelOptics' and a scene's defaults; a scene may
#: declare others): the azimuth of the light shading the red, green and blue channel, and
#: their elevation; and its marker grid in pixels
DIGIT_LIGHT_AZIMUTHS = (90.0, 210.0, 330.0)
DIGIT_LIGHT_ELEVATION = 35.0
MARKER_SPACING = 12
MARKER_RADIUS = 1.6
LIGHT_ELEVATION = np.deg2rad(DIGIT_LIGHT_ELEVATION)
LIGHT_AZIMUTHS = np.deg2rad(DIGIT_LIGHT_AZIMUTHS)  # red, green, blue lights
SLOPE_GAIN = 160.0  # DN per unit of (n . l - sin(elevation))
DEPTH_GAIN = 28.0  # DN at full gel compression
NOISE_SIGMA = 2.0  # DN, per pixel and channel
MARKER_DARKENING = 0.55
MARKER_SHIFT = 2.5  # lateral marker shift (pixels) per unit slope


@dataclass(frozen=True)
class GelOptics:
    """Sensor optics: gel size (height, width) in m, image size (rows, cols), pinhole distance
    behind the gel in m, saturation depth in m, membrane smoothing length in m; the
    illumination: the azimuth in degrees of the light shading each colour channel (red, green,
    blue) and their elevation in degrees (defaults: the DIGIT-like sensor's GelSight layout,
    `LIGHT_AZIMUTHS`, `LIGHT_ELEVATION`)."""

    gel_size: tuple[float, float]
    image_size: tuple[int, int]
    camera_distance: float
    saturation: float
    smoothing: float
    light_azimuths: tuple[float, float, float] = DIGIT_LIGHT_AZIMUTHS
    light_elevation: float = DIGIT_LIGHT_ELEVATION

    @property
    def pixel_size(self) -> float:
        """Metres per pixel on the gel plane (square pixels: width / cols)."""
        return self.gel_size[1] / self.image_size[1]


def sensor_background(seed_seq: list[int], image_size: tuple[int, int]) -> np.ndarray:
    """A sensor's smooth background (uint8 H x W x 3): tinted base colour, vignetting,
    per-channel colour-cast gradient and a few faint blobs, all drawn from `seed_seq`."""
    rng = np.random.default_rng(seed_seq)
    h, w = image_size
    y, x = np.meshgrid(np.linspace(-1, 1, h), np.linspace(-1, 1, w), indexing="ij")
    base = np.array([105.0, 125.0, 150.0]) + rng.uniform(-15, 15, size=3)
    img = np.broadcast_to(base, (h, w, 3)).astype(np.float64).copy()
    vignette = 1.0 - rng.uniform(0.15, 0.35) * (x**2 + y**2) / 2
    img *= vignette[..., None]
    cast = rng.uniform(-12, 12, size=(2, 3))
    img += x[..., None] * cast[0] + y[..., None] * cast[1]
    for _ in range(int(rng.integers(3, 7))):
        cx, cy = rng.uniform(-1, 1, size=2)
        rad = rng.uniform(0.1, 0.4)
        amp = rng.uniform(-8, 8, size=3)
        img += np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * rad**2))[..., None] * amp
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def ray_directions(optics: GelOptics) -> np.ndarray:
    """Unit ray directions (H, W, 3) in the sensor frame from the pinhole at z = -distance
    through each pixel centre of the gel's rest plane (z = 0, +z toward the object)."""
    (gh, gw), (h, w) = optics.gel_size, optics.image_size
    xs = ((np.arange(w) + 0.5) / w - 0.5) * gw
    ys = (0.5 - (np.arange(h) + 0.5) / h) * gh
    x, y = np.meshgrid(xs, ys)
    vec = np.stack([x, y, np.full_like(x, optics.camera_distance)], axis=-1)
    return vec / np.linalg.norm(vec, axis=-1, keepdims=True)


def _roi(
    optics: GelOptics, centre: np.ndarray, half: np.ndarray
) -> tuple[int, int, int, int] | None:
    """Pixel box (r0, r1, c0, c1) whose rays can meet an axis-aligned box (sensor frame,
    `centre` +- `half`) below the rest plane; None when the box is entirely above it."""
    zmin = centre[2] - half[2]
    if zmin >= 0.0:
        return None
    d = optics.camera_distance
    mag = d / (d + max(zmin, -0.9 * d))
    lo = np.minimum(centre[:2] - half[:2], (centre[:2] - half[:2]) * mag)
    hi = np.maximum(centre[:2] + half[:2], (centre[:2] + half[:2]) * mag)
    (gh, gw), (h, w) = optics.gel_size, optics.image_size
    c0 = int(np.floor((lo[0] / gw + 0.5) * w)) - 1
    c1 = int(np.ceil((hi[0] / gw + 0.5) * w)) + 1
    r0 = int(np.floor((0.5 - hi[1] / gh) * h)) - 1
    r1 = int(np.ceil((0.5 - lo[1] / gh) * h)) + 1
    r0, r1, c0, c1 = max(r0, 0), min(r1, h), max(c0, 0), min(c1, w)
    if r0 >= r1 or c0 >= c1:
        return None
    return r0, r1, c0, c1


_GROUP_OBJECT = np.array([0, 1, 0, 0, 0, 0], dtype=np.uint8)


def height_field_rays(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    geom: int,
    frame_pos: np.ndarray,
    frame_mat: np.ndarray,
    optics: GelOptics,
    directions: np.ndarray,
) -> np.ndarray:
    """Indentation (m, >= 0, float64 H x W) of geom `geom` below the gel's rest plane.

    frame_pos/frame_mat: the gel frame (rest-plane centre, 3x3 rotation, +z toward the
    object); directions: `ray_directions(optics)`. Only geoms in group 1 (the object) are hit.
    """
    h, w = optics.image_size
    out = np.zeros((h, w))
    rot = np.asarray(frame_mat).reshape(3, 3)
    gmat = data.geom_xmat[geom].reshape(3, 3)
    aabb = model.geom_aabb[geom]
    centre = rot.T @ (data.geom_xpos[geom] + gmat @ aabb[:3] - frame_pos)
    half = np.abs(rot.T @ gmat) @ aabb[3:]
    roi = _roi(optics, centre, half)
    if roi is None:
        return out
    r0, r1, c0, c1 = roi
    local = directions[r0:r1, c0:c1].reshape(-1, 3)
    vec = np.ascontiguousarray(local @ rot.T)
    n = local.shape[0]
    pnt = frame_pos - optics.camera_distance * rot[:, 2]
    geomid = np.empty(n, dtype=np.int32)
    dist = np.empty(n)
    mujoco.mj_multiRay(
        model,
        data,
        pnt,
        vec.ravel(),
        _GROUP_OBJECT,
        0,
        -1,
        geomid,
        dist,
        None,
        n,
        2.0 * optics.camera_distance,
    )
    z = -optics.camera_distance + dist * local[:, 2]
    depth = np.where(geomid >= 0, np.maximum(-z, 0.0), 0.0)
    out[r0:r1, c0:c1] = depth.reshape(r1 - r0, c1 - c0)
    return out


def height_field_depth(
    renderer: mujoco.Renderer, data: mujoco.MjData, camera: int, optics: GelOptics
) -> np.ndarray:
    """Indentation from an offscreen depth render of an orthographic camera placed
    `camera_distance` below the gel looking up (only group 1 visible); the benchmark's
    alternative to `height_field_rays`."""
    opt = mujoco.MjvOption()
    opt.geomgroup[:] = 0
    opt.geomgroup[1] = 1
    renderer.update_scene(data, camera=camera, scene_option=opt)
    depth = renderer.render().astype(np.float64)
    return np.maximum(optics.camera_distance - depth, 0.0)


def gel_compression(height: np.ndarray, saturation: float) -> np.ndarray:
    """Saturating gel compression s * tanh(h / s): linear for small h, at most s, finite."""
    return saturation * np.tanh(np.asarray(height, dtype=np.float64) / saturation)


def marker_pattern(
    image_size: tuple[int, int], spacing: int = MARKER_SPACING, radius: float = MARKER_RADIUS
):
    """Marker darkness map (float32 H x W in [0, 1]): a square grid of Gaussian dots."""
    h, w = image_size
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    dy = (y - spacing / 2) % spacing - spacing / 2
    dx = (x - spacing / 2) % spacing - spacing / 2
    return np.exp(-(dx**2 + dy**2) / (2 * radius**2)).astype(np.float32)


# Gaussian quantiles at the 65536 mid-points of (0, 1): noise = table[uniform uint16], an exact
# inverse-CDF draw quantised to 16 bits, several times faster than rng.standard_normal for a
# frame.
_NOISE_TABLE = (NOISE_SIGMA * ndtri((np.arange(65536) + 0.5) / 65536)).astype(np.float32)


def sensor_noise(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Seeded per-pixel Gaussian read noise (float32, sd NOISE_SIGMA DN, 16-bit inverse CDF)."""
    return _NOISE_TABLE[rng.integers(0, 65536, size=shape, dtype=np.uint16)]


def tactile_shading(
    height: np.ndarray,
    background: np.ndarray,
    optics: GelOptics,
    *,
    noise: np.random.Generator | None = None,
    markers: np.ndarray | None = None,
) -> np.ndarray:
    """Shade an indentation height field (m) onto a sensor background -> uint8 frame.

    noise: seeded generator for pixel noise (None: no noise). markers: `marker_pattern`
    output (None: no markers). Deterministic for the same inputs and generator state.
    """
    h, w = optics.image_size
    if height.shape != (h, w) or background.shape != (h, w, 3):
        raise ValueError(
            f"tactile_shading: height {height.shape} / background {background.shape} do not "
            f"match the sensor image size {(h, w)}"
        )
    frame = background.astype(np.float32)
    sigma = optics.smoothing / optics.pixel_size
    nz_r = np.flatnonzero(np.any(height > 0, axis=1))
    if nz_r.size:
        nz_c = np.flatnonzero(np.any(height > 0, axis=0))
        # Work on the box around the imprint, widened by the blur radius: outside it the
        # smoothed height is exactly 0 and so is the shading term.
        m = (int(np.ceil(3 * sigma)) if sigma > 0 else 0) + 2
        r0, r1 = max(nz_r[0] - m, 0), min(nz_r[-1] + 1 + m, h)
        c0, c1 = max(nz_c[0] - m, 0), min(nz_c[-1] + 1 + m, w)
        hc = gel_compression(height[r0:r1, c0:c1], optics.saturation).astype(np.float32)
        if sigma > 0:
            k = 2 * int(np.ceil(3 * sigma)) + 1
            hc = cv2.GaussianBlur(
                hc, (k, k), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REPLICATE
            )
        scale = np.float32(0.5 / optics.pixel_size)
        gx = cv2.Sobel(hc, cv2.CV_32F, 1, 0, ksize=1, borderType=cv2.BORDER_REPLICATE) * scale
        gy = cv2.Sobel(hc, cv2.CV_32F, 0, 1, ksize=1, borderType=cv2.BORDER_REPLICATE) * -scale
        inv = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
        elevation = np.deg2rad(optics.light_elevation)
        ce, se = np.float32(np.cos(elevation)), np.float32(np.sin(elevation))
        shade = np.empty(hc.shape + (3,), dtype=np.float32)
        depth_term = np.float32(DEPTH_GAIN / optics.saturation) * hc
        for c, az in enumerate(np.deg2rad(np.asarray(optics.light_azimuths, dtype=np.float64))):
            a, b = np.float32(-ce * np.cos(az)), np.float32(-ce * np.sin(az))
            lam = (a * gx + b * gy + se) * inv
            shade[..., c] = np.float32(SLOPE_GAIN) * (np.maximum(lam, 0) - se) + depth_term
        frame[r0:r1, c0:c1] += shade
        if markers is not None:
            mx = np.arange(w, dtype=np.float32)[None, :].repeat(h, 0)
            my = np.arange(h, dtype=np.float32)[:, None].repeat(w, 1)
            mx[r0:r1, c0:c1] += gx * np.float32(MARKER_SHIFT)
            my[r0:r1, c0:c1] -= gy * np.float32(MARKER_SHIFT)
            shifted = cv2.remap(markers, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            frame *= (1.0 - MARKER_DARKENING * shifted)[..., None]
    if markers is not None and not nz_r.size:
        frame *= (1.0 - MARKER_DARKENING * markers)[..., None]
    if noise is not None:
        frame += sensor_noise(noise, (h, w, 3))
    return np.clip(np.rint(frame), 0, 255).astype(np.uint8)
