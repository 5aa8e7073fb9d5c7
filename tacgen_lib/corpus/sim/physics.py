"""Object physics in a compiled scene: geometry, mass, hardness, friction, and the press.

The press (paper's exploratory action) is a lumped series-spring model run by MuJoCo:

- the sensor's elastomer is a light plate on a vertical slide joint with a spring of
  `gel_stiffness` N/m (gravity-compensated, critically damped); its MuJoCo displacement is the
  gel indentation depth, so the weight and the press force push it down by F / K_gel;
- the object's hardness is its contact compliance: the object geom's solref is set in
  MuJoCo's direct (negative) form so that its contacts act as a spring of `stiffness` N/m in
  total, i.e. soft objects conform (approach further) under the same force;
- the measured force is the sum of MuJoCo's normal contact forces between object and plate
  (`mj_contactForce`), averaged over the last `measure_steps` steps.

MuJoCo's constraint stiffness is mass-normalised; with impedance `imp` constant (solimp
dmin = dmax), a contact row with reference stiffness S (solref = (-S, -2 sqrt S)) carries
f = S |r| / (imp R) at rest, R = (1 - imp) / imp * diag(A) its regulariser (efc_R). We therefore
set S = K imp R / n for n contacts, and clamp S <= 0.2 / dt^2 for stability; the
`stiffness` reported is the effective K after the clamp.

The press starts from the analytic equilibrium (plate at -F/K_gel, object approaching by F/K)
so that a short settle suffices; the force itself always comes from MuJoCo's contacts.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tacgen_lib.corpus.sim.scenes import Scene

__all__ = [
    "ObjectPhysics",
    "PressResult",
    "SceneRuntime",
    "shape_volume",
    "shape_inertia",
    "apply_object",
    "press_object",
    "PhysicsWarning",
    "state_problems",
]

GRAVITY = 9.81
IMPEDANCE = 0.9  # solimp dmin = dmax: constant impedance, so stiffness is linear in r
RIGID_STIFFNESS = 5.0e4  # N/m, contact stiffness used when contact_compliance is not declared


class PhysicsWarning(RuntimeError):
    """MuJoCo raised a warning (instability, NaN, contact overflow) during a simulation."""


@dataclass(frozen=True)
class ObjectPhysics:
    """One object: shape, characteristic size s (m), density (kg/m^3), contact stiffness (N/m),
    friction coefficient, and yaw (rad) of its presentation pose."""

    shape: str
    size: float
    density: float
    stiffness: float
    friction: float
    yaw: float = 0.0

    @property
    def volume(self) -> float:
        return shape_volume(self.shape, self.size)

    @property
    def mass(self) -> float:
        return self.density * self.volume


@dataclass(frozen=True)
class PressResult:
    """What one press measured: MuJoCo normal force (N), gel depth (m), object approach (m),
    effective contact stiffness (N/m), number of contacts, object pose (pos, quat)."""

    force_normal: float
    gel_depth: float
    approach: float
    stiffness: float
    n_contacts: int
    pos: np.ndarray
    quat: np.ndarray


def _dims(shape: str, s: float) -> np.ndarray:
    """MuJoCo geom size vector (3,) of `shape` with characteristic size s (see scenes.SHAPES)."""
    if shape == "cube":
        return np.array([s / 2, s / 2, s / 2])
    if shape == "sphere":
        return np.array([s / 2, 0.0, 0.0])
    if shape == "cylinder":
        return np.array([s / 2, s / 2, 0.0])
    if shape == "capsule":
        return np.array([s / 4, s / 2, 0.0])
    if shape == "ellipsoid":
        return np.array([s / 2, 0.35 * s, 0.25 * s])
    raise ValueError(f"unknown shape {shape!r}")


def _half_height(shape: str, s: float) -> float:
    """Distance from the object's centre to its lowest point in the presentation pose."""
    return {"cube": s / 2, "sphere": s / 2, "cylinder": s / 2, "capsule": s / 4}.get(
        shape, 0.25 * s
    )


def shape_volume(shape: str, s: float) -> float:
    """Volume (m^3) of `shape` with characteristic size s (m)."""
    d = _dims(shape, s)
    if shape == "cube":
        return float(8 * d[0] * d[1] * d[2])
    if shape == "sphere":
        return float(4 / 3 * np.pi * d[0] ** 3)
    if shape == "cylinder":
        return float(np.pi * d[0] ** 2 * 2 * d[1])
    if shape == "capsule":
        return float(np.pi * d[0] ** 2 * 2 * d[1] + 4 / 3 * np.pi * d[0] ** 3)
    return float(4 / 3 * np.pi * d[0] * d[1] * d[2])


def shape_inertia(shape: str, s: float, mass: float) -> np.ndarray:
    """Principal inertia (kg m^2) in the body frame (capsule axis along body x)."""
    d = _dims(shape, s)
    if shape == "cube":
        i = mass * (2 * d[0]) ** 2 / 6
        return np.array([i, i, i])
    if shape == "sphere":
        i = 0.4 * mass * d[0] ** 2
        return np.array([i, i, i])
    if shape == "cylinder":
        r, h = d[0], 2 * d[1]
        ix = mass * (3 * r**2 + h**2) / 12
        return np.array([ix, ix, mass * r**2 / 2])
    if shape == "capsule":
        r, length = d[0], 2 * d[1]
        vc, vh = np.pi * r**2 * length, 4 / 3 * np.pi * r**3
        mc, mh = mass * vc / (vc + vh), mass * vh / (vc + vh)
        axial = mc * r**2 / 2 + mh * 2 * r**2 / 5
        perp = mc * (length**2 / 12 + r**2 / 4) + mh * (
            2 * r**2 / 5 + length**2 / 4 + 3 * length * r / 8
        )
        return np.array([axial, perp, perp])
    a, b, c = d
    return mass / 5 * np.array([b**2 + c**2, a**2 + c**2, a**2 + b**2])


def _rbound_aabb(shape: str, s: float) -> tuple[float, np.ndarray]:
    d = _dims(shape, s)
    if shape == "cube":
        return float(np.linalg.norm(d)), d.copy()
    if shape == "sphere":
        return float(d[0]), np.full(3, d[0])
    if shape == "cylinder":
        return float(np.hypot(d[0], d[1])), np.array([d[0], d[0], d[1]])
    if shape == "capsule":
        return float(d[0] + d[1]), np.array([d[0], d[0], d[0] + d[1]])
    return float(d.max()), d.copy()


class SceneRuntime:
    """A compiled scene plus its MjData and the ids the simulator needs (reused per sample)."""

    def __init__(self, scene: Scene, model: mujoco.MjModel):
        self.scene = scene
        self.model = model
        self.data = mujoco.MjData(model)
        m = model
        self.object_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "object")
        self.object_joint = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "object_free")
        self.object_qpos = int(m.jnt_qposadr[self.object_joint])
        self.object_dof = int(m.jnt_dofadr[self.object_joint])
        self.shape_geom = {
            s: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"obj_{s}") for s in scene.shapes
        }
        self.material = {
            name: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_MATERIAL, f"mat_{name}")
            for name in ("plain", "checkered", "striped", "speckled")
        }
        self.active_geom = -1
        self.active: ObjectPhysics | None = None
        if scene.kind == "press":
            self.gel_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "gel_pad")
            joint = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "gel_z")
            self.gel_qpos = int(m.jnt_qposadr[joint])
            self.gel_dof = int(m.jnt_dofadr[joint])

    # -- object parameters ---------------------------------------------------------------------
    def contact_force(self, geom_a: int, geom_b: int) -> tuple[float, int]:
        """Sum of MuJoCo normal contact forces (N) between two geoms, and the contact count."""
        d = self.data
        total, n, f6 = 0.0, 0, np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            if {int(c.geom1), int(c.geom2)} == {geom_a, geom_b} and c.efc_address >= 0:
                mujoco.mj_contactForce(self.model, d, i, f6)
                total += f6[0]
                n += 1
        return total, n


def apply_object(rt: SceneRuntime, obj: ObjectPhysics, *, rgba=None, texture="plain") -> None:
    """Make `obj` the scene's active object: geom, size, mass, inertia, friction, appearance."""
    m, scene = rt.model, rt.scene
    if obj.shape not in rt.shape_geom:
        raise ValueError(
            f"scene {scene.name!r}: shape {obj.shape!r} is not declared in objects.shapes "
            f"({', '.join(scene.shapes)})"
        )
    for _shape, g in rt.shape_geom.items():
        m.geom_group[g] = 3
        m.geom_contype[g] = 0
        m.geom_conaffinity[g] = 0
    g = rt.shape_geom[obj.shape]
    m.geom_group[g] = 1
    m.geom_contype[g] = 1
    m.geom_conaffinity[g] = 1
    m.geom_size[g] = _dims(obj.shape, obj.size)
    rbound, aabb = _rbound_aabb(obj.shape, obj.size)
    m.geom_rbound[g] = rbound
    m.geom_aabb[g] = np.concatenate([np.zeros(3), aabb])
    m.geom_friction[g] = [obj.friction, 0.005, 0.0001]
    m.geom_condim[g] = 3 if scene.has("friction_shear") else 1
    m.geom_solimp[g] = [IMPEDANCE, IMPEDANCE, 0.001, 0.5, 2.0]
    m.geom_matid[g] = rt.material[texture if scene.has("texture") else "plain"]
    if rgba is not None:
        m.mat_rgba[m.geom_matid[g]] = rgba
    b = rt.object_body
    m.body_mass[b] = obj.mass
    m.body_inertia[b] = shape_inertia(obj.shape, obj.size, obj.mass)
    if scene.kind == "press":
        # Critical damping of the plate + object on the gel spring.
        m.dof_damping[rt.gel_dof] = 2.0 * np.sqrt(
            scene.gel_stiffness * (obj.mass + scene.plate_mass)
        )
    mujoco.mj_setConst(m, rt.data)
    rt.active_geom, rt.active = g, obj


def yaw_quat(yaw: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation by `yaw` about world z."""
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def presentation_pose(rt: SceneRuntime) -> None:
    """Object at rest on the undeformed gel (lowest point at z = 0), plate at rest: the pose
    the RGB frame is rendered in. It depends on shape, size and yaw only, never on physics."""
    obj = rt.active
    d = rt.data
    d.qpos[:] = rt.model.qpos0
    d.qvel[:] = 0
    if rt.scene.kind == "press":
        d.qpos[rt.gel_qpos] = 0.0
    a = rt.object_qpos
    d.qpos[a : a + 3] = [0.0, 0.0, _half_height(obj.shape, obj.size)]
    d.qpos[a + 3 : a + 7] = yaw_quat(obj.yaw)
    mujoco.mj_forward(rt.model, d)


def state_problems(data: mujoco.MjData) -> list[str]:
    """What is wrong with a simulation's state: the MuJoCo warnings raised, else
    ["non-finite state"] where a position or acceleration is not finite; empty if nothing."""
    d = data
    bad = [mujoco.mjtWarning(i).name for i in range(len(d.warning)) if d.warning[i].number > 0]
    if bad or not np.all(np.isfinite(d.qpos)) or not np.all(np.isfinite(d.qacc)):
        return bad or ["non-finite state"]
    return []


def _check(rt: SceneRuntime, where: str) -> None:
    bad = state_problems(rt.data)
    if bad:
        raise PhysicsWarning(
            f"scene {rt.scene.name!r}: {where}: MuJoCo warnings {bad} "
            f"for object {rt.active}; lower the timestep or the stiffness range"
        )


def press_object(
    rt: SceneRuntime,
    press_force: float,
    *,
    offset_xy: tuple[float, float] = (0.0, 0.0),
    dyaw: float = 0.0,
    settle_steps: int | None = None,
) -> PressResult:
    """Press the active object into the gel with `press_force` N (plus its weight if gravity is
    declared) and measure the MuJoCo contact force at rest. Raises PhysicsWarning on any
    MuJoCo warning or non-finite state."""
    scene, m, d, obj = rt.scene, rt.model, rt.data, rt.active
    if scene.kind != "press" or obj is None:
        raise ValueError(f"scene {scene.name!r}: press_object needs a press scene with an object")
    g = rt.active_geom
    weight = obj.mass * GRAVITY if scene.has("gravity") else 0.0
    force = weight + (press_force if scene.has("press") else 0.0)
    k_target = obj.stiffness if scene.has("contact_compliance") else RIGID_STIFFNESS
    # Analytic warm start: plate and object at their predicted equilibrium.
    mujoco.mj_resetData(m, d)
    depth0 = force / scene.gel_stiffness
    approach0 = force / k_target
    d.qpos[rt.gel_qpos] = -depth0
    a = rt.object_qpos
    h = _half_height(obj.shape, obj.size)
    d.qpos[a : a + 3] = [offset_xy[0], offset_xy[1], -depth0 + h - approach0]
    d.qpos[a + 3 : a + 7] = yaw_quat(obj.yaw + dyaw)
    # Calibrate the contact's reference stiffness from the contacts at the warm start.
    m.geom_solref[g] = [-1.0, -2.0]
    mujoco.mj_forward(m, d)
    rows = [
        d.efc_R[d.contact[i].efc_address]
        for i in range(d.ncon)
        if g in (int(d.contact[i].geom1), int(d.contact[i].geom2)) and d.contact[i].efc_address >= 0
    ]
    n = max(len(rows), 1)
    reg = float(np.mean(rows)) if rows else (1 - IMPEDANCE) / (IMPEDANCE * obj.mass)
    s_ref = k_target * IMPEDANCE * reg / n
    s_max = 0.2 / scene.timestep**2
    s_ref = min(s_ref, s_max)
    k_eff = s_ref * n / (IMPEDANCE * reg)
    m.geom_solref[g] = [-s_ref, -2.0 * np.sqrt(s_ref)]
    if scene.has("press"):
        d.xfrc_applied[rt.object_body, 2] = -press_force
    steps = scene.settle_steps if settle_steps is None else settle_steps
    measure = min(scene.measure_steps, steps)
    total, count = 0.0, 0
    for step in range(steps):
        mujoco.mj_step(m, d)
        if step >= steps - measure:
            f, count = rt.contact_force(g, rt.gel_geom)
            total += f
    _check(rt, "press")
    depth = -float(d.qpos[rt.gel_qpos])
    pos = d.qpos[a : a + 3].copy()
    lowest = pos[2] - h
    return PressResult(
        force_normal=total / measure,
        gel_depth=depth,
        approach=max(0.0, -lowest),
        stiffness=float(k_eff),
        n_contacts=count,
        pos=pos,
        quat=d.qpos[a + 3 : a + 7].copy(),
    )
