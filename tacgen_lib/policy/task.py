"""The grasp-lift-hold task (scene `grasp_lift`): episodes, the grip-force window, the lift.

An **episode** is one object (a sphere: a round imprint on the pads) on the table between the pads of a parallel-jaw gripper. Its
appearance (size, colour, texture) is drawn independently of its physics (density -> mass,
friction coefficient, contact stiffness -> crush limit), so vision sees the size but not the
grip force the object needs.

The policy's action is one **grip force** F (N, the normal force each pad's motor applies).
The lift then runs physics only: the pads close on the object with F (ramped), the gripper
lifts it by `lift_height` and holds it for `hold_time`. An episode succeeds when

- the object ends at the lift height (not *dropped*: it rose at least half the lift),
- it slid less than `slip_limit` relative to the pads during the hold (*slip*), and
- no pad's MuJoCo normal contact force ever exceeded the object's crush limit (*crush*):
  soft objects are fragile, crush_limit = stiffness x crush_depth.

So each object has a **window** of good grip forces: the lower end from weight and friction
(2 mu F >= m (g + a), Coulomb on both pads, a the lift's peak acceleration), the upper end from
compliance (F <= crush_limit). `window` gives both ends analytically; the physics decides.

Holding contact model (google-deepmind/mujoco#3328): elliptic friction cones, a high
`impratio` and `noslip_iterations`, so a held object's creep under gravity (the creep floor)
stays far below `slip_limit`; `creep_floor` measures it and the tests check the margin.

Effects: the lift phase declares only physics (gravity, contact_compliance, friction_shear);
the palpation phase (palpation.py) adds rgb/texture/tactile. Each phase builds the task's model
(`task_xml`) with the physics of exactly the effects it declares disabled otherwise, so a lift
never builds a renderer or a tactile sensor.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from tacgen_lib.corpus.sim.physics import state_problems
from tacgen_lib.corpus.sim.scenes import (
    Scene,
    disable_undeclared,
    texture_asset_xml,
    texture_assets,
    validate_scene,
)
from tacgen_lib.policy.settings import PolicySettings

__all__ = [
    "Episode",
    "Outcome",
    "FAILURE_MODES",
    "sample_episode",
    "sample_episodes",
    "window",
    "phase_scene",
    "task_xml",
    "GraspTask",
    "rollout",
    "creep_floor",
]

GRAVITY = 9.81
FAILURE_MODES = ("success", "slip", "crush", "drop", "miss")
TEXTURES = ("plain", "checkered", "striped", "speckled")
PAD_HALF = (0.004, 0.015, 0.015)  # pad box half-sizes (thickness, width, height), m
PAD_MASS = 0.05  # kg per finger
HOLD_SETTLE = 0.1  # s of the hold before slip is measured
IMPEDANCE = 0.9  # constant contact impedance (solimp dmin = dmax)
FINGER_GAP = 0.001  # m between each pad and the object at the start


@dataclass(frozen=True)
class Episode:
    """One grasp episode: visible appearance and invisible physics (SI units)."""

    episode_id: str
    size: float  # sphere diameter (visible)
    rgba: tuple[float, float, float, float]  # colour (visible, independent of physics)
    texture: str  # visible, independent of physics
    density: float  # invisible
    friction: float  # invisible
    stiffness: float  # N/m, invisible: contact compliance; crush_limit = stiffness * crush_depth
    crush_limit: float  # N per pad

    @property
    def mass(self) -> float:
        return self.density * np.pi / 6 * self.size**3

    def visible(self) -> np.ndarray:
        """The attributes vision can see (size, colour, texture one-hot)."""
        tex = [float(self.texture == t) for t in TEXTURES]
        return np.array([self.size, *self.rgba[:3], *tex])


@dataclass(frozen=True)
class Outcome:
    """What one lift did: success, failure mode, and the measurements that decided it."""

    success: bool
    mode: str  # one of FAILURE_MODES
    grip_force: float  # N commanded per pad
    lift: float  # m the object rose (end of hold)
    slip: float  # m the object slid relative to the pads during the hold
    peak_force: float  # N, largest per-pad MuJoCo normal contact force
    steps: int


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def sample_episode(settings: PolicySettings, seed: int, index: int, prefix: str = "ep") -> Episode:
    """Draw episode `index` from its own seeded stream, rejection-sampled so the window's width
    crush_limit / lower end lies in [min_window_ratio, max_window_ratio] (narrow windows whose
    position varies 30-fold across objects: guessing from size alone mostly misses). Appearance is drawn from a separate stream
    from physics, so colour and texture carry no information about mass, friction or compliance."""
    s = settings
    look = np.random.default_rng([seed, index, 0xA9])
    size = float(look.uniform(*s.size_range))
    rgba = (*(float(x) for x in look.uniform(0.15, 0.95, size=3)), 1.0)
    texture = TEXTURES[int(look.integers(len(TEXTURES)))]
    phys = np.random.default_rng([seed, index, 0x9F])
    for _ in range(1000):
        density = _log_uniform(phys, *s.density_range)
        friction = float(phys.uniform(*s.friction_range))
        stiffness = _log_uniform(phys, *s.stiffness_range)
        ep = Episode(
            f"{prefix}-{index:05d}",
            size,
            rgba,
            texture,
            density,
            friction,
            stiffness,
            stiffness * s.crush_depth,
        )
        lo, hi = window(ep, s)
        if s.min_window_ratio * lo <= hi <= s.max_window_ratio * lo:
            return ep
    raise RuntimeError(f"episode {index}: no feasible window in 1000 draws; widen the ranges")


def sample_episodes(settings: PolicySettings, seed: int, n: int, prefix: str) -> list[Episode]:
    return [sample_episode(settings, seed, i, prefix) for i in range(n)]


def window(ep: Episode, settings: PolicySettings) -> tuple[float, float]:
    """The grip-force window (N per pad): (m (g + a_peak) / (2 mu), crush_limit)."""
    a_peak = np.pi**2 / 2 * settings.lift_height / settings.lift_time**2  # cosine profile
    return ep.mass * (GRAVITY + a_peak) / (2 * ep.friction), ep.crush_limit


def phase_scene(scene_decl: dict, effects: list[str], timestep: float) -> Scene:
    """The `grasp_lift` scene restricted to one phase's effects (which must be declared)."""
    undeclared = sorted(set(effects) - set(scene_decl["effects"]))
    if undeclared:
        raise ValueError(
            f"policy phase effects {undeclared} are not declared by scene 'grasp_lift' "
            f"(config/scenes.yaml: {sorted(scene_decl['effects'])})"
        )
    return validate_scene("grasp_lift", dict(scene_decl, effects=list(effects), timestep=timestep))


def task_xml(scene: Scene, settings: PolicySettings, size_max: float) -> str:
    """MJCF of the policy scene: a sphere on a table, a lifting carriage with two force-driven
    fingers (motor actuators on slide joints: ctrl = normal force per pad), pads as sensors.
    Only declared effects appear (cameras only with `rgb`, textures only with `texture`)."""
    px, py, pz = PAD_HALF
    tex = scene.has("texture")
    assets = ""
    if tex:
        assets = texture_asset_xml()
    mats = "".join(
        f'<material name="mat_{t}" rgba="0.5 0.5 0.5 1"'
        + (f' texture="tex_{t}"' if tex and t != "plain" else "")
        + "/>"
        for t in TEXTURES
    )
    cams = ""
    if scene.has("rgb"):
        c = scene.cameras[0]
        az, el = np.deg2rad(c["azimuth"]), np.deg2rad(c["elevation"])
        fwd = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        pos = np.array([0.0, 0.0, 0.025]) - c["distance"] * fwd
        cams = (
            '<body name="cam_target" pos="0 0 0.025"/>'
            f'<camera name="context0" mode="targetbody" target="cam_target" '
            f'pos="{pos[0]:.6f} {pos[1]:.6f} {pos[2]:.6f}" fovy="{c["fovy"]}"/>'
        )
    fingers = []
    for side, sign in (("left", -1.0), ("right", 1.0)):
        site = ""
        if scene.has("tactile"):
            # gel frame: rest plane on the pad's inner face, +z toward the object
            site = (
                f'<site name="{side}_pad" pos="{-sign * px} 0 0" '
                f'zaxis="{-sign} 0 0" size="0.001" group="4"/>'
            )
        fingers.append(
            f'<body name="{side}_finger" pos="{sign * (size_max / 2 + px + 0.03)} 0 0">'
            f'<joint name="{side}_slide" type="slide" axis="{-sign} 0 0" range="0 0.05" '
            f'damping="{settings.finger_damping}"/>'
            f'<geom name="{side}_pad_geom" type="box" size="{px} {py} {pz}" mass="0.05" '
            'rgba="0.55 0.6 0.62 1" condim="3" friction="1 0.005 0.0001" group="0"/>'
            f"{site}</body>"
        )
    return f"""
<mujoco model="grasp_lift">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{scene.timestep}" cone="elliptic" impratio="{settings.impratio}"
          noslip_iterations="{settings.noslip_iterations}" integrator="implicitfast"/>
  <visual><quality offsamples="0" shadowsize="0"/><map znear="0.01"/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.5 0.5 0.5" specular="0 0 0"/></visual>
  <asset>{assets}{mats}</asset>
  <worldbody>
    <light name="key" pos="0.1 -0.1 0.5" dir="-0.2 0.2 -1" castshadow="false"/>
    <geom name="table" type="plane" size="0.3 0.3 0.01" rgba="0.82 0.8 0.76 1" condim="3"
          friction="0.5 0.005 0.0001"/>
    {cams}
    <body name="carriage" pos="0 0 0.02" gravcomp="1">
      <joint name="lift" type="slide" axis="0 0 1" range="-0.01 0.2" damping="50"/>
      <inertial pos="0 0 0" mass="0.5" diaginertia="1e-3 1e-3 1e-3"/>
      {"".join(fingers)}
    </body>
    <body name="object" pos="0 0 0.02"><freejoint name="object_free"/>
      <geom name="object_geom" type="sphere" size="0.02" material="mat_plain"
            condim="3" group="1" priority="1"/>
    </body>
  </worldbody>
  <contact><exclude body1="world" body2="left_finger"/>
    <exclude body1="world" body2="right_finger"/>
    <exclude body1="left_finger" body2="right_finger"/></contact>
  <actuator>
    <position name="lift" joint="lift" kp="2000" kv="100" ctrlrange="-0.01 0.2"/>
    <motor name="left" joint="left_slide" ctrlrange="0 60"/>
    <motor name="right" joint="right_slide" ctrlrange="0 60"/>
  </actuator>
</mujoco>"""


class GraspTask:
    """A compiled phase of the task (physics + ids), reused across episodes.

    `set_episode` writes an episode's size, mass, friction, compliance and appearance into the
    model and resets the state: object on the table, pads FINGER_GAP from its faces, carriage
    centred on the object's mid-height."""

    def __init__(self, scene: Scene, settings: PolicySettings):
        self.scene = scene
        self.settings = settings
        self.model = mujoco.MjModel.from_xml_string(
            task_xml(scene, settings, settings.size_range[1]), texture_assets()
        )
        m = self.model
        disable_undeclared(m, scene, sensors=False)  # the pads are read by rays, not sensors
        self.data = mujoco.MjData(m)
        ids = mujoco.mj_name2id
        self.object_body = ids(m, mujoco.mjtObj.mjOBJ_BODY, "object")
        self.object_geom = ids(m, mujoco.mjtObj.mjOBJ_GEOM, "object_geom")
        self.pads = [ids(m, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_pad_geom") for s in ("left", "right")]
        self.finger_qpos = [
            int(m.jnt_qposadr[ids(m, mujoco.mjtObj.mjOBJ_JOINT, f"{s}_slide")])
            for s in ("left", "right")
        ]
        self.lift_qpos = int(m.jnt_qposadr[ids(m, mujoco.mjtObj.mjOBJ_JOINT, "lift")])
        self.obj_qpos = int(m.jnt_qposadr[ids(m, mujoco.mjtObj.mjOBJ_JOINT, "object_free")])
        self.act_lift = ids(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "lift")
        self.act_fingers = [ids(m, mujoco.mjtObj.mjOBJ_ACTUATOR, s) for s in ("left", "right")]
        self.materials = {t: ids(m, mujoco.mjtObj.mjOBJ_MATERIAL, f"mat_{t}") for t in TEXTURES}
        self.finger_x0 = [
            float(m.body_pos[m.jnt_bodyid[m.actuator_trnid[a, 0]]][0]) for a in self.act_fingers
        ]
        self.episode: Episode | None = None
        self.carriage_z0 = 0.0

    def set_episode(self, ep: Episode) -> None:
        m, d, s = self.model, self.data, ep.size
        g = self.object_geom
        m.geom_size[g] = [s / 2, 0.0, 0.0]
        m.geom_rbound[g] = s / 2
        m.geom_aabb[g] = [0, 0, 0, s / 2, s / 2, s / 2]
        m.geom_friction[g] = [ep.friction, 0.005, 0.0001]
        m.geom_solimp[g] = [IMPEDANCE, IMPEDANCE, 0.001, 0.5, 2.0]
        m.geom_solref[g] = [-1.0, -2.0]
        b = self.object_body
        m.body_mass[b] = ep.mass
        m.body_inertia[b] = [0.1 * ep.mass * s**2] * 3  # solid sphere, 2/5 m r^2
        mujoco.mj_setConst(m, d)
        if self.scene.has("contact_compliance"):
            self._calibrate_compliance(ep)
        m.geom_matid[g] = self.materials[ep.texture if self.scene.has("texture") else "plain"]
        m.mat_rgba[m.geom_matid[g]] = ep.rgba
        self._place(s, FINGER_GAP)
        self.episode = ep

    def _place(self, s: float, gap: float) -> None:
        """Object resting on the table, carriage at its mid-height, pads `gap` from its faces."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        # object resting on the table, carriage at its mid-height, pads FINGER_GAP away
        d.qpos[self.obj_qpos : self.obj_qpos + 3] = [0.0, 0.0, s / 2]
        d.qpos[self.obj_qpos + 3 : self.obj_qpos + 7] = [1, 0, 0, 0]
        self.carriage_z0 = s / 2 - 0.02
        d.qpos[self.lift_qpos] = self.carriage_z0
        for q, x0 in zip(self.finger_qpos, self.finger_x0, strict=True):
            d.qpos[q] = abs(x0) - PAD_HALF[0] - s / 2 - gap
        d.ctrl[self.act_lift] = self.carriage_z0
        mujoco.mj_forward(m, d)

    def _calibrate_compliance(self, ep: Episode) -> None:
        """Set the object's contact stiffness so that each pad's contacts act as one spring of
        ep.stiffness N/m (the press scene's calibration, tacgen_lib.corpus.sim.physics):
        with constant impedance, a row of reference stiffness S carries f = S r / (imp R) at
        rest, so S = K imp R / n for the n contact rows of a pad (R from MuJoCo's efc_R with
        the pads touching), clamped to timeconst >= 2 dt for stability."""
        m, d, g = self.model, self.data, self.object_geom
        self._place(ep.size, -1e-5)
        rows = [
            d.efc_R[d.contact[i].efc_address]
            for i in range(d.ncon)
            if {int(d.contact[i].geom1), int(d.contact[i].geom2)} & set(self.pads)
            and g in (int(d.contact[i].geom1), int(d.contact[i].geom2))
            and d.contact[i].efc_address >= 0
        ]
        if not rows:
            raise RuntimeError(f"episode {ep.episode_id}: pads do not touch the object")
        n = len(rows) / 2
        s_ref = min(ep.stiffness * IMPEDANCE * float(np.mean(rows)) / n, 0.25 / m.opt.timestep**2)
        m.geom_solref[g] = [-s_ref, -2.0 * np.sqrt(s_ref)]

    def pad_forces(self) -> list[float]:
        """Per-pad sum of MuJoCo normal contact forces with the object (N), by mj_contactForce
        (measured faster than a numpy-vectorised read of efc_force for the few contacts here)."""
        d, out, f6 = self.data, [0.0, 0.0], np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            pair = {int(c.geom1), int(c.geom2)}
            for k, p in enumerate(self.pads):
                if pair == {self.object_geom, p} and c.efc_address >= 0:
                    mujoco.mj_contactForce(self.model, d, i, f6)
                    out[k] += f6[0]
        return out

    def object_z(self) -> float:
        return float(self.data.qpos[self.obj_qpos + 2])

    def carriage_z(self) -> float:
        return float(self.data.qpos[self.lift_qpos])

    def check(self, where: str) -> None:
        bad = state_problems(self.data)
        if bad:
            raise RuntimeError(
                f"scene 'grasp_lift': {where}: MuJoCo warnings {bad} "
                f"for episode {self.episode}; lower the timestep or the stiffness range"
            )

    def grip(self, force: float, t: float, ramp: float) -> None:
        """Both pads push with min(1, t/ramp) * force (smooth ramp: no impact spike)."""
        self.data.ctrl[self.act_fingers] = force * min(1.0, t / ramp) if ramp > 0 else force

    def step_until(self, t_end: float, fn) -> None:
        """Step the physics to time t_end calling fn(t) before each step."""
        d, m = self.data, self.model
        while d.time < t_end - 0.5 * m.opt.timestep:
            fn(d.time)
            mujoco.mj_step(m, d)


def rollout(task: GraspTask, ep: Episode, grip_force: float) -> Outcome:
    """Physics-only lift of episode `ep` with `grip_force` N per pad (the policy's action).

    1. close: ramp both pads to grip_force over `close_time` (s), carriage still;
    2. lift: raise the carriage by `lift_height` with a cosine profile over `lift_time`;
    3. hold: keep it there for `hold_time`; slip = change of (carriage z - object z) over the
       hold after the first HOLD_SETTLE s (the soft contacts' elastic settling, ~0.3 mm).
    Crush: the largest per-pad normal contact force over all steps above ep.crush_limit."""
    s = task.settings
    task.set_episode(ep)
    peak = 0.0
    z_obj0 = task.object_z()
    close, lift, hold = s.close_time, s.lift_time, s.hold_time

    def ctrl(t: float) -> None:
        nonlocal peak
        task.grip(grip_force, t, s.close_time)
        u = min(max((t - close) / lift, 0.0), 1.0)
        task.data.ctrl[task.act_lift] = task.carriage_z0 + s.lift_height * 0.5 * (
            1 - np.cos(np.pi * u)
        )
        peak = max(peak, *task.pad_forces())

    task.step_until(close, ctrl)
    task.step_until(close + lift + HOLD_SETTLE, ctrl)
    in_contact = peak > 0.0
    rel0 = task.carriage_z() - task.object_z()  # after the contacts' elastic settling
    task.step_until(close + lift + hold, ctrl)
    peak = max(peak, *task.pad_forces())
    task.check("lift")
    rel1 = task.carriage_z() - task.object_z()
    risen = task.object_z() - z_obj0
    slip = rel1 - rel0
    if not in_contact:
        mode = "miss"
    elif peak > ep.crush_limit:
        mode = "crush"
    elif risen < 0.5 * s.lift_height:
        mode = "drop"
    elif slip > s.slip_limit:
        mode = "slip"
    else:
        mode = "success"
    steps = int(round(task.data.time / task.model.opt.timestep))
    return Outcome(mode == "success", mode, float(grip_force), risen, slip, peak, steps)


def creep_floor(task: GraspTask, ep: Episode, grip_force: float, hold_time: float) -> float:
    """Creep speed (m/s) of a held object: its slide relative to the pads over `hold_time`
    after the lift, with a force inside the window (the floor the slip criterion must clear)."""
    s = replace(task.settings, hold_time=hold_time)
    t = GraspTask(task.scene, s)
    out = rollout(t, ep, grip_force)
    return max(out.slip, 0.0) / (hold_time - HOLD_SETTLE)
