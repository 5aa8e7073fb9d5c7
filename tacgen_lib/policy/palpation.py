"""The palpation phase: what the policy observes before it chooses a grip force.

Per episode, once (the action comes after it and does not change it, so every policy reuses
the same observation):

1. the RGB context frame of the object on the table (appearance: size, colour, texture);
2. two **squeeze-and-heft** probes: both pads close on the object with a light force
   (`palpation_forces`, each below every object's crush limit) and both pads' tactile frames
   are rendered with the project's renderer (tacgen_lib.corpus.sim.tactile: ray-cast
   indentation -> three-light shading): the depth and spread of the imprint carry the
   compliance (the same force indents a soft object further). Then the carriage rises by
   `heft_height` and the pads are rendered again: when the pads carry the weight
   (2 mu F_p >= m g) the imprint stays centred; when they slide up the object (which stays on
   the table) the imprint moves down the pad and fades (a sliding soft contact sheds its
   penetration in MuJoCo): weight against friction, the friction/shear effect. The carriage
   returns and the pads relax between probes.

The palpation compiles the scene with its own declared effects (config policy phases: rgb,
texture, tactile, sensor_noise on top of the physics); the lift (task.rollout) never does.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tacgen_lib.corpus.sim import tactile
from tacgen_lib.corpus.sim.render import prefer_headless_egl
from tacgen_lib.policy.task import Episode, GraspTask

__all__ = ["Palpation", "PadOptics", "palpate", "pad_background", "PAD_NAMES", "frame_names"]

PAD_NAMES = ("left_pad", "right_pad")


def frame_names(n_probes: int) -> list[str]:
    """Tactile frame columns (moment x pad, fixed order): each probe's squeeze and heft."""
    return [
        f"tactile_{moment}_{k}_{pad}"
        for k in range(n_probes)
        for moment in ("squeeze", "heft")
        for pad in PAD_NAMES
    ]


@dataclass(frozen=True)
class Palpation:
    """One episode's observation: RGB frame, tactile frames (name -> uint8 HxWx3), and the
    sensor backgrounds (pad -> uint8 HxWx3) the frames were shaded on."""

    rgb: np.ndarray | None
    frames: dict[str, np.ndarray]
    held: tuple[bool, ...]  # diagnostic (not an observation): did each heft lift the object


class PadOptics:
    """The pads' gel optics and ray directions (a pad is 30 x 30 mm, the camera 3 cm behind)."""

    def __init__(self, image_size: tuple[int, int]):
        self.optics = tactile.GelOptics((0.03, 0.03), tuple(image_size), 0.03, 0.002, 0.0006)
        self.directions = tactile.ray_directions(self.optics)


def pad_background(seed: int, pad: int, image_size: tuple[int, int]) -> np.ndarray:
    """The fixed background of pad `pad` (0 left, 1 right) of the policy's gripper."""
    return tactile.sensor_background([seed, pad, 0x9AD], tuple(image_size))


class _Renderer:
    """Context-camera renderer, created on first use (scenes without `rgb` never create one)."""

    def __init__(self) -> None:
        self.r: mujoco.Renderer | None = None

    def __call__(self, task: GraspTask, size: tuple[int, int]) -> np.ndarray:
        if self.r is None:
            prefer_headless_egl()
            self.r = mujoco.Renderer(task.model, int(size[0]), int(size[1]))
            self.r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
            self.r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            self.r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
        self.r.update_scene(task.data, camera="context0")
        return self.r.render().copy()


_RENDERERS: dict[int, _Renderer] = {}


def palpate(task: GraspTask, ep: Episode, optics: PadOptics, *, noise_seed: int) -> Palpation:
    """Run the palpation phase of `ep` on a task compiled with the palpation's effects."""
    s, scene = task.settings, task.scene
    task.set_episode(ep)
    rgb = None
    if scene.has("rgb"):
        rgb = _RENDERERS.setdefault(id(task), _Renderer())(task, s.image_size)
    m = task.model
    sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, p) for p in PAD_NAMES]
    rng = np.random.default_rng([noise_seed, 0x7AC]) if scene.has("sensor_noise") else None
    frames: dict[str, np.ndarray] = {}
    held = []
    squeeze, rise, settle = s.close_time, 0.15, 0.05

    def render(moment: str) -> None:
        if not scene.has("tactile"):
            return
        d = task.data
        for pad, site in enumerate(sites):
            h = tactile.height_field_rays(
                m,
                d,
                task.object_geom,
                d.site_xpos[site],
                d.site_xmat[site],
                optics.optics,
                optics.directions,
            )
            bg = pad_background(s.seed, pad, optics.optics.image_size)
            frames[f"tactile_{moment}_{PAD_NAMES[pad]}"] = tactile.tactile_shading(
                h, bg, optics.optics, noise=rng
            )

    for k, force in enumerate(s.palpation_forces):
        t0 = task.data.time
        z_obj0 = task.object_z()

        def ctrl(t: float, t0: float = t0, force: float = force) -> None:
            task.grip(force, t - t0, squeeze)
            u = min(max((t - t0 - squeeze) / rise, 0.0), 1.0)
            task.data.ctrl[task.act_lift] = task.carriage_z0 + s.heft_height * 0.5 * (
                1 - np.cos(np.pi * u)
            )

        # 1. squeeze: the imprint's depth and spread carry the compliance
        task.step_until(t0 + squeeze, ctrl)
        render(f"squeeze_{k}")
        # 2. heft: the imprint stays centred if the pads carry the weight, slides and fades if not
        task.step_until(t0 + squeeze + rise + settle, ctrl)
        task.check("palpation")
        held.append(task.object_z() - z_obj0 > 0.5 * s.heft_height)
        render(f"heft_{k}")

        # 3. release and return: the carriage goes back down, the pads open
        t1 = task.data.time

        def back(t: float, t1: float = t1) -> None:
            task.data.ctrl[task.act_fingers] = 0.0
            u = min(max((t - t1) / rise, 0.0), 1.0)
            task.data.ctrl[task.act_lift] = task.carriage_z0 + s.heft_height * 0.5 * (
                1 + np.cos(np.pi * u)
            )

        task.step_until(t1 + rise + settle, back)
    return Palpation(rgb=rgb, frames=frames, held=tuple(held))
