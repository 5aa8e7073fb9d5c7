"""Render N tactile + RGB frames in this one process and print the RSS growth (JSON on stdout).

Run by tests/test_faults.py in a subprocess, so the RSS is this loop's alone:

    python tests/leak_render.py <scenes.yaml> <frames> <warmup>

Each frame: a MuJoCo RGB render of the context camera (EGL, like simulate_corpus) and a
tactile frame (ray-cast height field, shading with seeded noise), both PNG-encoded. The object
changes every 100 frames (a press settles it on the gel), so the renderer sees new geometry.
RSS is read after `warmup` frames (caches, the GL context and allocator pools are in place)
and again at the end.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import yaml
from sim_scenes import gel_heights

from tacgen_lib.corpus.sim import physics, tactile
from tacgen_lib.corpus.sim.render import render_rgb
from tacgen_lib.corpus.sim.scenes import compile_scene, validate_scene
from tacgen_lib.io.images import encode_png

RGB_SIZE = (64, 64)
TACTILE_SIZE = (60, 80)


def rss_mb() -> float:
    with open("/proc/self/status") as fh:
        line = next(row for row in fh if row.startswith("VmRSS:"))
    return int(line.split()[1]) / 1024


def main(scenes_file: str, frames: int, warmup: int) -> None:
    scene = validate_scene("paired_press", yaml.safe_load(open(scenes_file))["paired_press"])
    rt = physics.SceneRuntime(scene, compile_scene(scene))
    optics = tactile.GelOptics(
        gel_size=scene.gel_size,
        image_size=TACTILE_SIZE,
        camera_distance=scene.gel_camera_distance,
        saturation=scene.gel_saturation,
        smoothing=scene.gel_smoothing,
    )
    directions = tactile.ray_directions(optics)
    background = tactile.sensor_background([0, 0, 0xB6], TACTILE_SIZE)
    frame_site = rt.model.site("gel_frame").id
    state = {"rt": rt, "renderer": None}
    rng = np.random.default_rng(0)
    shapes = ("cube", "sphere", "cylinder")
    t0 = time.perf_counter()
    before = None
    nbytes = 0
    for i in range(frames):
        if i % 100 == 0:
            obj = physics.ObjectPhysics(shapes[(i // 100) % 3], 0.02, 800.0, 3000.0, 0.6, 0.1 * i)
            physics.apply_object(rt, obj, rgba=(0.2, 0.5, 0.8, 1.0))
            physics.press_object(rt, scene.press_force)
        height = gel_heights(rt, optics, directions=directions, site=frame_site)
        tac = tactile.tactile_shading(height, background, optics, noise=rng)
        rgb = render_rgb(state, RGB_SIZE)
        nbytes += len(encode_png(tac)) + len(encode_png(rgb))
        if i + 1 == warmup:
            before = rss_mb()
    after = rss_mb()
    print(
        json.dumps(
            {
                "frames": frames,
                "warmup": warmup,
                "rss_before_mb": before,
                "rss_after_mb": after,
                "growth_mb": after - before,
                "seconds": time.perf_counter() - t0,
                "png_bytes": nbytes,
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
