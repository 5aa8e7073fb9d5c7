"""Benchmark of the policy stage's simulation (tacgen_lib.policy). Prints figures; not a test.

    .venv/bin/python benchmarks/bench_policy.py [--episodes 40]

1. Reference: bare mj_step of the lift-phase model (no control, no contact queries).
2. The physics-only lift (task.rollout: the policy's rollout): physics steps/s, episodes/s.
3. The same lift on a model compiled with every palpation effect, rendering the RGB camera and
   both pads' tactile frames every 20 ms of simulated time: what observing during the lift
   would cost (the stage renders once per episode, in the palpation, instead).
4. The palpation phase per episode (two squeeze-and-heft probes, 1 RGB + 8 tactile frames).
"""

from __future__ import annotations

import argparse
import time

import mujoco  # noqa: I001
import yaml
from machine import describe, parse_args, sized

import tacgen_lib.corpus.sim  # noqa: F401  (sets MUJOCO_GL=egl before mujoco is imported)
from tacgen_lib.corpus.sim import tactile
from tacgen_lib.policy import data, oracle, palpation, task
from tacgen_lib.policy.settings import PolicySettings

DECL = yaml.safe_load(open("config/scenes.yaml"))["grasp_lift"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=40)
    args = parse_args(ap, {"episodes": 2})
    s = PolicySettings()
    eps = task.sample_episodes(s, 77, args.episodes, "bench")
    forces = [oracle.oracle_force(ep, s) for ep in eps]
    print(describe())

    lift = data.compile_phase(DECL, s, "lift")
    # 1. bare stepping of the same model and state
    lift.set_episode(eps[0])
    n = sized(5000, 100)
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(lift.model, lift.data)
    bare = n / (time.perf_counter() - t0)
    print(f"1. bare mj_step (lift model, 1 object):        {bare:10.0f} steps/s")

    # 2. physics-only lift
    t0 = time.perf_counter()
    steps = sum(task.rollout(lift, ep, f).steps for ep, f in zip(eps, forces, strict=True))
    dt = time.perf_counter() - t0
    print(
        f"2. physics-only lift (rollout):               {steps / dt:10.0f} steps/s, "
        f"{len(eps) / dt:6.1f} episodes/s ({steps / dt / bare:.2f} of bare stepping)"
    )

    # 3. the lift with rendering every 20 ms
    full = data.compile_phase(DECL, s, "palpation")
    optics = palpation.PadOptics(s.tactile_size)
    renderer = palpation._Renderer()
    sites = [
        mujoco.mj_name2id(full.model, mujoco.mjtObj.mjOBJ_SITE, p) for p in palpation.PAD_NAMES
    ]
    every = int(round(0.02 / s.timestep))
    bg = palpation.pad_background(s.seed, 0, s.tactile_size)
    t0 = time.perf_counter()
    steps = 0
    for ep, f in zip(eps, forces, strict=True):
        full.set_episode(ep)
        k = 0
        while full.data.time < s.close_time + s.lift_time + s.hold_time:
            full.grip(f, full.data.time, s.close_time)
            mujoco.mj_step(full.model, full.data)
            k += 1
            if k % every == 0:
                renderer(full, s.image_size)
                d = full.data
                for site in sites:
                    h = tactile.height_field_rays(
                        full.model,
                        d,
                        full.object_geom,
                        d.site_xpos[site],
                        d.site_xmat[site],
                        optics.optics,
                        optics.directions,
                    )
                    tactile.tactile_shading(h, bg, optics.optics)
        steps += k
    dt3 = time.perf_counter() - t0
    print(
        f"3. lift rendering RGB + 2 pads every 20 ms:   {steps / dt3:10.0f} steps/s, "
        f"{len(eps) / dt3:6.1f} episodes/s ({dt3 / dt:.1f}x the physics-only lift)"
    )

    # 4. palpation, once per episode
    t0 = time.perf_counter()
    for i, ep in enumerate(eps):
        palpation.palpate(full, ep, optics, noise_seed=i)
    dt4 = time.perf_counter() - t0
    print(f"4. palpation (1 RGB + 8 tactile frames):      {len(eps) / dt4:6.1f} episodes/s")
    per_policy = dt / len(eps)
    print(
        f"   a policy's held-out rollout costs {1e3 * per_policy:.0f} ms/episode; observing "
        f"during the lift would cost {1e3 * dt3 / len(eps):.0f} ms/episode"
    )


if __name__ == "__main__":
    main()
