"""The grasp_lift policy scene: a 2-finger gripper with tactile pads closes on and lifts an
object of declared size, mass and friction (scenes.yaml `objects: {size, mass, friction}`).

`grasp_lift` runs a scripted close-then-lift rollout and reports whether it stayed stable
(finite state, no MuJoCo warnings), how high the object rose, and the pads' tactile frames.
The learned policy (DESIGN: policy stage) will drive the same actuators.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tacgen_lib.corpus.sim import physics, tactile
from tacgen_lib.corpus.sim.scenes import Scene, compile_scene

__all__ = ["GraspResult", "grasp_lift"]


@dataclass(frozen=True)
class GraspResult:
    """Outcome of one scripted grasp-and-lift rollout."""

    lift_height: float  # m the object's centre rose
    grip_force: float  # N, total MuJoCo normal force pads -> object at the end
    steps: int
    pad_frames: dict[str, np.ndarray]  # sensor name -> uint8 tactile frame (tactile declared)
    pad_depth: dict[str, float]  # sensor name -> max indentation (m)


def grasp_lift(
    scene: Scene,
    *,
    close_time: float = 0.3,
    lift_time: float = 0.5,
    lift: float = 0.05,
    image_size: tuple[int, int] = (60, 60),
    seed: int = 0,
) -> GraspResult:
    """Close the fingers for `close_time` s, then raise the gripper by `lift` m over
    `lift_time` s. Raises physics.PhysicsWarning on MuJoCo warnings or non-finite state."""
    if scene.kind != "grasp_lift":
        raise ValueError(f"scene {scene.name!r}: grasp_lift needs a 'grasp_lift' scene")
    model = compile_scene(scene)
    rt = physics.SceneRuntime(scene, model)
    size = scene.object.get("size", 0.04)
    mass = scene.object.get("mass", 0.2)
    shape = scene.shapes[0]
    obj = physics.ObjectPhysics(
        shape, size, mass / physics.shape_volume(shape, size), 2.0e4,
        scene.object.get("friction", 1.0),
    )  # fmt: skip
    physics.apply_object(rt, obj)
    g = rt.active_geom
    model.geom_solref[g] = [max(0.004, 2 * scene.timestep), 1.0]
    if not scene.has("contact_compliance"):
        model.geom_solimp[g] = [0.95, 0.99, 0.001, 0.5, 2.0]
    d = rt.data
    mujoco.mj_resetData(model, d)
    mujoco.mj_forward(model, d)
    z0 = float(d.xpos[rt.object_body, 2])
    n_close = int(round(close_time / scene.timestep))
    n_lift = int(round(lift_time / scene.timestep))
    lift_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, "lift")
    fingers = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, s) for s in ("left", "right")]
    for step in range(n_close + n_lift):
        d.ctrl[fingers] = 0.03
        d.ctrl[lift_id] = (
            0.0 if step < n_close else lift * min(1.0, (step - n_close) / (0.6 * n_lift))
        )
        mujoco.mj_step(model, d)
    physics._check(rt, "grasp_lift")
    pads = [
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_pad_geom")
        for s in ("left", "right")
    ]
    grip = sum(rt.contact_force(g, p)[0] for p in pads)
    frames: dict[str, np.ndarray] = {}
    depths: dict[str, float] = {}
    if scene.has("tactile"):
        optics = tactile.GelOptics((0.024, 0.024), image_size, 0.03, 0.002, 0.0004)
        dirs = tactile.ray_directions(optics)
        background = tactile.sensor_background([seed, 0xFA], image_size)
        for name in scene.sensors:
            site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
            h = tactile.height_field_rays(
                model, d, g, d.site_xpos[site], d.site_xmat[site], optics, dirs
            )
            depths[name] = float(h.max())
            frames[name] = tactile.tactile_shading(h, background, optics)
    return GraspResult(
        lift_height=float(d.xpos[rt.object_body, 2]) - z0,
        grip_force=float(grip),
        steps=n_close + n_lift,
        pad_frames=frames,
        pad_depth=depths,
    )
