"""Benchmark of the simulated corpus (tacgen_lib.corpus.sim): tactile frame rate, per-sample time,
and the cost of each declared effect. Prints figures; not a test.

    .venv/bin/python benchmarks/bench_sim.py [--samples 60] [--frames 300] [--states 40]

1. Tactile frames/s at 120x160 (height field + shading, PNG excluded) for the two ways of
   getting the height field from MuJoCo: mj_multiRay (one ray per pixel, object box only) and
   an offscreen orthographic depth render (mujoco.Renderer, EGL/llvmpipe); one process, then
   two processes (2 cores) for the rays method.
2. Per-sample time of simulate_shard on paired_press (RGB + tactile + nominal + jittered
   presses + PNG).
3. Effect costs: per-sample time with each effect removed, and a minimal scene.
"""

from __future__ import annotations

import argparse
import copy
import multiprocessing as mp
import time

import mujoco  # noqa: I001
import numpy as np
import yaml
from machine import parse_args

import tacgen_lib.corpus.sim  # noqa: F401  (sets MUJOCO_GL=egl before mujoco is imported)
from tacgen_lib.corpus.sim import corpus, physics, render, samples, tactile
from tacgen_lib.corpus.sim.scenes import compile_scene, scene_xml, validate_scene

SCENES = yaml.safe_load(open("config/scenes.yaml"))
PAIRED = {
    "name": "bench",
    "kind": "simulated",
    "design": "paired",
    "seed": 1,
    "scene": "paired_press",
    "sensors": 4,
    "presses": 8,
}


def pressed_states(n: int):
    """n pressed objects (qpos snapshots) drawn like the paired corpus, in the corpus's model
    (`compile_scene`) with an orthographic camera under the gel for the depth method."""
    scene = validate_scene("paired_press", SCENES["paired_press"])
    xml = scene_xml(scene).replace(
        "</worldbody>",
        f'<camera name="gel_cam" pos="0 0 -{scene.gel_camera_distance}" euler="3.14159265 0 0" '
        f'projection="orthographic" fovy="{scene.gel_size[0]}"/></worldbody>',
    )
    rt = physics.SceneRuntime(scene, compile_scene(scene, xml))
    cfg = samples.CorpusSettings.from_config(dict(PAIRED, n=n))
    states = []
    for i in range(n):
        spec = samples.sample_spec(cfg, scene, i)
        physics.apply_object(rt, spec.obj)
        res = physics.press_object(rt, scene.press_force)
        states.append((spec.obj, rt.data.qpos.copy(), res.gel_depth))
    optics = tactile.GelOptics(
        scene.gel_size,
        (120, 160),
        scene.gel_camera_distance,
        scene.gel_saturation,
        scene.gel_smoothing,
    )
    return rt, states, optics


def frames(method: str, n_frames: int, n_states: int) -> float:
    """Tactile frames per second of one process (height field + shading + noise)."""
    rt, states, optics = pressed_states(n_states)
    dirs = tactile.ray_directions(optics)
    bg = tactile.sensor_background([1, 0, 0xB6], optics.image_size)
    renderer = None
    if method == "depth":
        render.prefer_headless_egl()
        renderer = mujoco.Renderer(rt.model, *optics.image_size)
        renderer.enable_depth_rendering()
        cam = mujoco.mj_name2id(rt.model, mujoco.mjtObj.mjOBJ_CAMERA, "gel_cam")
    rng = np.random.default_rng(0)
    prepared = []
    m = rt.model
    for obj, qpos, depth in states:  # object switching is not part of the frame cost
        physics.apply_object(rt, obj)
        g = rt.active_geom
        geo = (m.geom_size[g].copy(), m.geom_aabb[g].copy(), float(m.geom_rbound[g]))
        prepared.append((g, geo, qpos, depth))
    t0, done = time.perf_counter(), 0
    while done < n_frames:
        for geom, (size, aabb, rbound), qpos, depth in prepared:
            m.geom_group[list(rt.shape_geom.values())] = 3
            m.geom_group[geom] = 1
            m.geom_size[geom], m.geom_aabb[geom], m.geom_rbound[geom] = size, aabb, rbound
            rt.data.qpos[:] = qpos
            mujoco.mj_kinematics(rt.model, rt.data)
            if method == "rays":
                raw = tactile.height_field_rays(
                    rt.model, rt.data, geom, np.zeros(3), np.eye(3).ravel(), optics, dirs
                )
            else:
                raw = tactile.height_field_depth(renderer, rt.data, cam, optics)
            tactile.tactile_shading(np.minimum(raw, depth), bg, optics, noise=rng)
            done += 1
    return done / (time.perf_counter() - t0)


def _worker(args):
    return frames(*args)


def per_sample_ms(scene_decl: dict, n: int) -> float:
    scenes = {"s": scene_decl}
    cfg = dict(PAIRED, n=n, scene="s")
    corpus.simulate_shard(dict(cfg, n=2), scenes, 0, 1)  # warm-up: compile, GL context
    t0 = time.perf_counter()
    corpus.simulate_shard(cfg, scenes, 0, 1)
    return 1e3 * (time.perf_counter() - t0) / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=60)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--states", type=int, default=40, help="pressed objects the frames cycle")
    a = parse_args(ap, {"samples": 2, "frames": 4, "states": 2})

    print("== tactile frames/s at 120x160 (height field + shading + noise, no PNG) ==")
    fps = {m: frames(m, a.frames, a.states) for m in ("rays", "depth")}
    for m, v in fps.items():
        print(f"  1 process, {m:5s}: {v:7.0f} frames/s ({1e3 / v:.2f} ms/frame)")
    # agreement of the two height fields on one pressed sphere (precision of depth buffer)
    with mp.get_context("spawn").Pool(2) as pool:
        two = sum(pool.map(_worker, [("rays", a.frames, a.states)] * 2))
    print(f"  2 processes, rays: {two:7.0f} frames/s  (target >= 400)")
    print(
        f"  method used by the corpus: rays (ratio rays/depth in one process: "
        f"{fps['rays'] / fps['depth']:.2f}); rays need no GL context, are float64-exact, "
        "and scale across processes without sharing llvmpipe threads"
    )

    print(f"\n== per-sample time, paired_press, {a.samples} samples ==")
    full = copy.deepcopy(SCENES["paired_press"])
    base = per_sample_ms(full, a.samples)
    print(f"  full scene: {base:.1f} ms/sample (RGB 224x224 + tactile + 1+8 presses + PNG)")

    print("\n== cost of each effect (ms/sample saved when left out) ==")
    print(f"  {'effect':20s} {'ms/sample':>10s} {'saved':>8s}")
    for effect in full["effects"]:
        decl = copy.deepcopy(full)
        decl["effects"] = [e for e in full["effects"] if e != effect]
        ms = per_sample_ms(decl, a.samples)
        print(f"  {effect:20s} {ms:10.1f} {base - ms:8.1f}")
    for extra in ("shadows", "markers"):
        decl = copy.deepcopy(full)
        decl["effects"] = full["effects"] + [extra]
        ms = per_sample_ms(decl, a.samples)
        print(f"  +{extra:19s} {ms:10.1f} {base - ms:8.1f}")
    minimal = copy.deepcopy(full)
    minimal["effects"] = ["gravity", "press", "tactile"]
    ms = per_sample_ms(minimal, a.samples)
    print(
        f"  minimal (gravity, press, tactile): {ms:.1f} ms/sample, saves {base - ms:.1f} "
        f"({100 * (1 - ms / base):.0f}%)"
    )


if __name__ == "__main__":
    main()
