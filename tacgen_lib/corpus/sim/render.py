"""One simulated sample's frames: the compiled scene and its renderer kept once per process
(`scene_runtime`), the RGB frame (`render_rgb`, offscreen through EGL on the CPU:
`prefer_headless_egl`), and the tactile frame of a press added to its sensor's seeded
background (`tactile_frame`, `sensor_background`).
"""

from __future__ import annotations

import functools
import os
from typing import Any

import mujoco
import numpy as np

from tacgen_lib.corpus.sim import physics, tactile
from tacgen_lib.corpus.sim.samples import CorpusSettings, SampleSpec
from tacgen_lib.corpus.sim.scenes import Scene, compile_scene
from tacgen_lib.io.images import encode_png

_RUNTIMES: dict[tuple, dict[str, Any]] = {}


def scene_runtime(scene: Scene, cfg: CorpusSettings) -> dict[str, Any]:
    key = (repr(scene), tuple(cfg.image_size), tuple(cfg.tactile_size))
    if key not in _RUNTIMES:
        rt = physics.SceneRuntime(scene, compile_scene(scene))
        optics = tactile.GelOptics(
            gel_size=scene.gel_size,
            image_size=(int(cfg.tactile_size[0]), int(cfg.tactile_size[1])),
            camera_distance=scene.gel_camera_distance,
            saturation=scene.gel_saturation,
            smoothing=scene.gel_smoothing,
            light_azimuths=scene.light_azimuths,
            light_elevation=scene.light_elevation,
        )
        _RUNTIMES[key] = {
            "rt": rt,
            "optics": optics,
            "directions": tactile.ray_directions(optics),
            "markers": (
                tactile.marker_pattern(
                    optics.image_size, spacing=scene.marker_spacing, radius=scene.marker_radius
                )
                if scene.has("markers")
                else None
            ),
            "renderer": None,
        }
    return _RUNTIMES[key]


def prefer_headless_egl() -> None:
    """Use EGL when no display exists and MUJOCO_GL asked for nothing else.

    mujoco picks its GL backend when first imported; if that happened before tacgen_lib.corpus.sim
    could default MUJOCO_GL to egl (e.g. `import mujoco` first), it chose GLFW, which needs
    an X display. Switch the backend class the renderer will use to EGL in that case.
    """
    if os.environ.get("DISPLAY") or os.environ.get("MUJOCO_GL", "egl").lower() != "egl":
        return
    from mujoco.rendering.classic import gl_context

    if getattr(gl_context.GLContext, "__module__", "").startswith("mujoco.glfw"):
        from mujoco import egl

        gl_context.GLContext = egl.GLContext


def render_rgb(state: dict[str, Any], image_size: tuple[int, int]) -> np.ndarray:
    """Render the context camera (uint8 H x W x 3) of the current MuJoCo state; the renderer is
    created on first use, so scenes without `rgb` never create one."""
    rt: physics.SceneRuntime = state["rt"]
    if state["renderer"] is None:
        prefer_headless_egl()
        state["renderer"] = mujoco.Renderer(rt.model, int(image_size[0]), int(image_size[1]))
        flags = state["renderer"].scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = int(rt.scene.has("shadows"))
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
    renderer = state["renderer"]
    renderer.update_scene(rt.data, camera="context0")
    return renderer.render().copy()


@functools.lru_cache(maxsize=64)
def _background_cached(seed: int, k: int, size: tuple[int, int]) -> np.ndarray:
    img = tactile.sensor_background([seed, k, 0xB6], size)
    img.flags.writeable = False
    return img


def sensor_background(cfg: CorpusSettings, k: int) -> np.ndarray:
    """Sensor k's background: seeded from (corpus seed, k) only, cached per process."""
    size = (int(cfg.tactile_size[0]), int(cfg.tactile_size[1]))
    return _background_cached(int(cfg.seed), int(k), size)


def sensor_id(cfg: CorpusSettings, k: int) -> str:
    return f"{cfg.name}/digit{k}"


def tactile_frame(state, spec_phys: SampleSpec, spec_pix: SampleSpec, cfg, press_force) -> bytes:
    """Press `spec_phys`'s object and shade its imprint on `spec_pix`'s sensor and noise."""
    rt: physics.SceneRuntime = state["rt"]
    scene = rt.scene
    res = physics.press_object(rt, press_force)
    frame_id = mujoco.mj_name2id(rt.model, mujoco.mjtObj.mjOBJ_SITE, "gel_frame")
    raw = tactile.height_field_rays(
        rt.model,
        rt.data,
        rt.active_geom,
        rt.data.site_xpos[frame_id],
        rt.data.site_xmat[frame_id],
        state["optics"],
        state["directions"],
    )
    height = np.minimum(raw, max(res.gel_depth, 0.0))
    noise = np.random.default_rng(spec_pix.pixel_seed) if scene.has("sensor_noise") else None
    img = tactile.tactile_shading(
        height,
        sensor_background(cfg, spec_pix.sensor),
        state["optics"],
        noise=noise,
        markers=state["markers"],
    )
    return encode_png(img, compression=int(cfg.png_compression)), res
