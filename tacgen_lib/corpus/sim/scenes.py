"""Scene declarations and their compilation to MuJoCo: only declared effects are simulated.

A scene (one entry of config/scenes.yaml) declares its kind, objects, sensors, cameras and a
list of **effects** drawn from `EFFECTS`. `compile_scene` builds the MJCF/MjModel with exactly
those effects:

- physics left out is switched off in `model.opt.disableflags` (gravity -> mjDSBL_GRAVITY,
  friction_shear -> frictionless contacts (condim 1) and mjDSBL_FRICTIONLOSS, no tactile
  sensor -> mjDSBL_SENSOR);
- render passes left out are never run: without `rgb` no camera and no renderer exist,
  without `shadows` lights do not cast shadows and the shadow map has size 0, without
  `texture` no texture asset is compiled;
- sensors left out are not built (without `tactile`: no gel site, no touch sensor, no rays).

Scene kinds: ``press`` (an object rests on a spring-loaded gel plate and is pressed into it,
the paired and controlled corpora) and ``grasp_lift`` (a 2-finger gripper with tactile pads
lifts an object, the policy scene). Units are SI throughout.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from tacgen_lib.corpus.sim import tactile

__all__ = [
    "EFFECTS",
    "SHAPES",
    "Scene",
    "validate_scene",
    "validate_scenes",
    "compile_scene",
    "disable_undeclared",
    "scene_xml",
]

#: The fixed effect vocabulary, with what each one switches on.
EFFECTS: dict[str, str] = {
    "gravity": "gravity acts on the object (weight presses it into the gel)",
    "contact_compliance": "per-object contact stiffness (solref/solimp) sets hardness",
    "friction_shear": "frictional contacts (condim 3, elliptic cone) with per-object friction",
    "press": "a fixed downward press force applied at the object's centre of mass",
    "press_jitter": "repeated presses under seeded force/placement jitter give force bands",
    "rgb": "the context camera renders an RGB frame",
    "texture": "objects carry textures in the RGB frame (otherwise plain colour)",
    "shadows": "lights cast shadows in the RGB frame",
    "tactile": "the gel sensor is built; its indentation height field is shaded to a frame",
    "sensor_noise": "seeded pixel noise is added to tactile frames",
    "markers": "the gel carries a grid of dark markers displaced by the indentation",
}

#: Primitive shapes and how the characteristic size s (metres) maps to MuJoCo geom sizes.
SHAPES: tuple[str, ...] = ("cube", "sphere", "cylinder", "capsule", "ellipsoid")

_SCENE_KEYS = {
    "kind",
    "effects",
    "objects",
    "sensors",
    "cameras",
    "timestep",
    "settle_steps",
    "measure_steps",
    "press",
    "gel",
    "description",
}
_OBJECT_KEYS = {"shapes", "size", "mass", "friction"}
_SENSOR_KEYS = {"name"}
_CAMERA_KEYS = {"name", "distance", "azimuth", "elevation", "fovy"}
_PRESS_KEYS = {"force", "jitter_force", "jitter_xy", "jitter_yaw"}
_GEL_KEYS = {
    "size",
    "stiffness",
    "plate_mass",
    "saturation",
    "smoothing",
    "camera_distance",
    "light_azimuths",
    "light_elevation",
    "marker_spacing",
    "marker_radius",
}
_KINDS = {"press", "grasp_lift"}

TEXTURES: tuple[str, ...] = ("plain", "checkered", "striped", "speckled")


@dataclass(frozen=True)
class Scene:
    """A validated scene declaration with defaults filled in (all lengths in metres)."""

    name: str
    kind: str
    effects: frozenset[str]
    shapes: tuple[str, ...]
    sensors: tuple[str, ...]
    cameras: tuple[dict[str, float], ...]
    timestep: float
    settle_steps: int
    measure_steps: int
    press_force: float
    jitter_force: float
    jitter_xy: float
    jitter_yaw: float
    gel_size: tuple[float, float]
    gel_stiffness: float
    plate_mass: float
    gel_saturation: float
    gel_smoothing: float
    gel_camera_distance: float
    object: dict[str, float] = field(default_factory=dict)
    # the sensor's illumination (degrees; red, green, blue) and marker grid (pixels), declared
    # under `gel`; defaults: the DIGIT-like sensor
    light_azimuths: tuple[float, float, float] = tactile.DIGIT_LIGHT_AZIMUTHS
    light_elevation: float = tactile.DIGIT_LIGHT_ELEVATION
    marker_spacing: int = tactile.MARKER_SPACING
    marker_radius: float = tactile.MARKER_RADIUS

    def has(self, effect: str) -> bool:
        """True when the scene declares `effect` (which must be in the vocabulary)."""
        if effect not in EFFECTS:
            raise ValueError(f"scene {self.name!r}: unknown effect {effect!r}")
        return effect in self.effects


def _check_keys(scene: str, where: str, got: Mapping[str, Any], allowed: set[str]) -> None:
    bad = sorted(set(got) - allowed)
    if bad:
        raise ValueError(
            f"scene {scene!r}: unknown key {where}{bad[0]!r} (allowed: {', '.join(sorted(allowed))})"
        )


def validate_scene(name: str, decl: Mapping[str, Any]) -> Scene:
    """Check one declaration (ValueError naming the scene and key) and fill in defaults."""
    if not isinstance(decl, Mapping):
        raise ValueError(
            f"scene {name!r}: declaration must be a mapping, got {type(decl).__name__}"
        )
    _check_keys(name, "", decl, _SCENE_KEYS)
    kind = decl.get("kind", "press")
    if kind not in _KINDS:
        raise ValueError(f"scene {name!r}: key 'kind': {kind!r} is not one of {sorted(_KINDS)}")
    effects = decl.get("effects")
    if not isinstance(effects, list | tuple) or not effects:
        raise ValueError(f"scene {name!r}: key 'effects' must be a non-empty list of effects")
    for e in effects:
        if e not in EFFECTS:
            raise ValueError(
                f"scene {name!r}: key 'effects': unknown effect {e!r} "
                f"(vocabulary: {', '.join(EFFECTS)})"
            )
    objects = dict(decl.get("objects", {}))
    _check_keys(name, "objects.", objects, _OBJECT_KEYS)
    shapes = tuple(objects.pop("shapes", SHAPES))
    for s in shapes:
        if s not in SHAPES:
            raise ValueError(f"scene {name!r}: key 'objects.shapes': unknown shape {s!r}")
    sensors = decl.get("sensors", [{"name": "gel"}] if kind == "press" else [])
    for i, s in enumerate(sensors):
        _check_keys(name, f"sensors[{i}].", s, _SENSOR_KEYS)
    cameras = decl.get("cameras", [{"name": "context"}])
    for i, c in enumerate(cameras):
        _check_keys(name, f"cameras[{i}].", c, _CAMERA_KEYS)
    press = dict(decl.get("press", {}))
    _check_keys(name, "press.", press, _PRESS_KEYS)
    gel = dict(decl.get("gel", {}))
    _check_keys(name, "gel.", gel, _GEL_KEYS)
    timestep = float(decl.get("timestep", 5e-4 if kind == "press" else 1e-3))
    if not 0 < timestep <= 0.01:
        raise ValueError(f"scene {name!r}: key 'timestep': {timestep} not in (0, 0.01] s")
    gel_size = tuple(float(v) for v in gel.get("size", [0.045, 0.06]))
    if len(gel_size) != 2 or min(gel_size) <= 0:
        raise ValueError(f"scene {name!r}: key 'gel.size' must be [height, width] in metres > 0")
    lights = tuple(float(v) for v in gel.get("light_azimuths", Scene.light_azimuths))
    if len(lights) != 3:
        raise ValueError(
            f"scene {name!r}: key 'gel.light_azimuths' must give 3 azimuths in degrees (the "
            f"red, green and blue lights), got {len(lights)}"
        )
    elevation = float(gel.get("light_elevation", Scene.light_elevation))
    if not 0.0 < elevation < 90.0:
        raise ValueError(f"scene {name!r}: key 'gel.light_elevation': {elevation} not in (0, 90)")
    spacing = int(gel.get("marker_spacing", Scene.marker_spacing))
    radius = float(gel.get("marker_radius", Scene.marker_radius))
    if spacing < 2 or not 0.0 < radius < spacing:
        raise ValueError(
            f"scene {name!r}: keys 'gel.marker_spacing' ({spacing} px, at least 2) and "
            f"'gel.marker_radius' ({radius} px, in (0, spacing)) do not make a marker grid"
        )
    return Scene(
        name=name,
        kind=kind,
        effects=frozenset(effects),
        shapes=shapes,
        sensors=tuple(str(s["name"]) for s in sensors),
        cameras=tuple(
            {
                "distance": float(c.get("distance", 0.16)),
                "azimuth": float(c.get("azimuth", 45.0)),
                "elevation": float(c.get("elevation", -40.0)),
                "fovy": float(c.get("fovy", 40.0)),
            }
            for c in cameras
        ),
        timestep=timestep,
        settle_steps=int(decl.get("settle_steps", 120)),
        measure_steps=int(decl.get("measure_steps", 10)),
        press_force=float(press.get("force", 0.5)),
        jitter_force=float(press.get("jitter_force", 0.05)),
        jitter_xy=float(press.get("jitter_xy", 0.001)),
        jitter_yaw=float(press.get("jitter_yaw", 0.05)),
        gel_size=(gel_size[0], gel_size[1]),
        gel_stiffness=float(gel.get("stiffness", 2000.0)),
        plate_mass=float(gel.get("plate_mass", 0.05)),
        gel_saturation=float(gel.get("saturation", 0.002)),
        gel_smoothing=float(gel.get("smoothing", 0.0006)),
        gel_camera_distance=float(gel.get("camera_distance", 0.05)),
        object={k: float(v) for k, v in objects.items()},
        light_azimuths=(lights[0], lights[1], lights[2]),
        light_elevation=elevation,
        marker_spacing=spacing,
        marker_radius=radius,
    )


def validate_scenes(scenes: Mapping[str, Any]) -> dict[str, Scene]:
    """Validate every scene of a scenes.yaml mapping (scene name -> declaration)."""
    if not isinstance(scenes, Mapping):
        raise ValueError("scenes: expected a mapping scene_name -> declaration")
    return {name: validate_scene(name, decl) for name, decl in scenes.items()}


# ---------------------------------------------------------------------------------------------
# MJCF


def _geom_for_shape(shape: str, s: float) -> tuple[str, str, str]:
    """(type, size attribute, euler) of the geom of `shape` with characteristic size s."""
    if shape == "cube":
        return "box", f"{s / 2} {s / 2} {s / 2}", "0 0 0"
    if shape == "sphere":
        return "sphere", f"{s / 2}", "0 0 0"
    if shape == "cylinder":
        return "cylinder", f"{s / 2} {s / 2}", "0 0 0"
    if shape == "capsule":
        return "capsule", f"{s / 4} {s / 2}", "0 1.5707963267948966 0"
    return "ellipsoid", f"{s / 2} {0.35 * s} {0.25 * s}", "0 0 0"


def _visual_xml(scene: Scene) -> str:
    shadow = 2048 if scene.has("shadows") else 0
    return (
        f'<visual><quality offsamples="0" shadowsize="{shadow}"/>'
        '<headlight ambient="0.35 0.35 0.35" diffuse="0.5 0.5 0.5" specular="0 0 0"/>'
        '<map znear="0.01"/></visual>'
    )


#: A texture's mark level: a MuJoCo texture multiplies the material's rgba, so a mark keeps
#: this fraction of the object's colour and the rest of the face keeps all of it.
TEXTURE_MARK = 0.3

#: Pixels of a texture face (one image, repeated on the six faces of a cube texture).
TEXTURE_FACE = 64


def texture_faces() -> dict[str, np.ndarray]:
    """Texture -> its grey face, a (`TEXTURE_FACE`, `TEXTURE_FACE`) array of 1 (the object's
    colour) and `TEXTURE_MARK` (a mark), for every texture of `TEXTURES` but plain.

    The patterns are the words of the caption at the size a frame shows them: checkered, a 2 x 2
    checkerboard per face; striped, six parallel bands per face; speckled, a fixed random 35 %
    of 4-pixel cells (seeded, the same on every run). MuJoCo's builtin checker with edge marks,
    which "striped" once was, draws tiles with dark rims: at the backbone's input a striped
    object looked checkered.
    """
    n = TEXTURE_FACE
    i = np.arange(n)
    mark = TEXTURE_MARK
    checker = np.where((i[:, None] * 2 // n + i[None, :] * 2 // n) % 2 == 0, 1.0, mark)
    bands = np.broadcast_to(np.where((i[:, None] * 6 // n) % 2 == 0, 1.0, mark), (n, n))
    cells = np.random.default_rng(0).random((n // 4, n // 4)) < 0.35
    speckle = np.where(cells, mark, 1.0).repeat(4, axis=0).repeat(4, axis=1)
    return {"checkered": checker, "striped": np.array(bands), "speckled": speckle}


@functools.cache
def texture_assets() -> dict[str, bytes]:
    """The PNG files `texture_asset_xml` names (``tex_<texture>.png``), for MuJoCo's
    ``from_xml_string(xml, assets)``: `texture_faces` as 8-bit grey RGB."""
    from tacgen_lib.io.images import encode_png  # OpenCV: only where a scene is compiled

    return {
        f"tex_{name}.png": encode_png(
            np.repeat(np.round(g * 255).astype(np.uint8)[:, :, None], 3, 2)
        )
        for name, g in texture_faces().items()
    }


def texture_asset_xml() -> str:
    """The MJCF ``<texture>`` of every texture but plain (those of `texture_faces`), a cube
    texture named ``tex_<texture>`` read from `texture_assets` (the corpus scenes and the
    policy task)."""
    return "".join(
        f'<texture name="tex_{t}" type="cube" file="tex_{t}.png"/>'
        for t in TEXTURES
        if t != "plain"
    )


def _assets_xml(scene: Scene) -> str:
    """Textures (only with `texture`) and one material per texture kind for the object."""
    parts = ["<asset>"]
    if scene.has("texture"):
        parts.append(texture_asset_xml())
    for t in TEXTURES:
        tex = f' texture="tex_{t}"' if scene.has("texture") and t != "plain" else ""
        parts.append(f'<material name="mat_{t}" rgba="0.5 0.5 0.5 1"{tex} specular="0.2"/>')
    parts.append("</asset>")
    return "".join(parts)


def _object_body_xml(scene: Scene, pos: str, s: float) -> str:
    """The object body: one geom per declared shape, all but the active one parked (group 3)."""
    geoms = []
    for shape in scene.shapes:
        gtype, size, euler = _geom_for_shape(shape, s)
        geoms.append(
            f'<geom name="obj_{shape}" type="{gtype}" size="{size}" euler="{euler}" group="3" '
            f'contype="0" conaffinity="0" priority="1" material="mat_plain" condim="3" '
            f'friction="0.8 0.005 0.0001"/>'
        )
    return (
        f'<body name="object" pos="{pos}"><freejoint name="object_free"/>'
        '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-5 1e-5 1e-5"/>'
        + "".join(geoms)
        + "</body>"
    )


def _camera_xml(scene: Scene, target: tuple[float, float, float]) -> str:
    if not scene.has("rgb"):
        return ""
    out = []
    for i, c in enumerate(scene.cameras):
        az, el, dist = np.deg2rad(c["azimuth"]), np.deg2rad(c["elevation"]), c["distance"]
        fwd = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        pos = np.asarray(target) - dist * fwd
        out.append(
            f'<camera name="context{i}" mode="targetbody" target="cam_target" '
            f'pos="{pos[0]:.6f} {pos[1]:.6f} {pos[2]:.6f}" fovy="{c["fovy"]}"/>'
        )
    return "".join(out)


def _press_xml(scene: Scene) -> str:
    """The press scene: a spring-loaded gel plate (the sensor's elastomer) and one object."""
    gh, gw = scene.gel_size
    cast = "true" if scene.has("shadows") else "false"
    tactile = scene.has("tactile")
    sensor_site = (
        f'<site name="gel_touch" type="box" size="{gw / 2} {gh / 2} 0.01" pos="0 0 0" '
        'rgba="0 0 0 0" group="4"/>'
        if tactile
        else ""
    )
    frame_site = '<site name="gel_frame" pos="0 0 0" size="0.001" group="4"/>' if tactile else ""
    sensors = '<sensor><touch name="gel_touch" site="gel_touch"/></sensor>' if tactile else ""
    return f"""
<mujoco model="{scene.name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{scene.timestep}" cone="elliptic" integrator="implicitfast"/>
  {_visual_xml(scene)}
  {_assets_xml(scene)}
  <worldbody>
    <light name="key" pos="0.1 -0.1 0.4" dir="-0.25 0.25 -1" castshadow="{cast}" diffuse="0.6 0.6 0.6"/>
    <geom name="table" type="plane" size="0.25 0.25 0.01" pos="0 0 -0.02" rgba="0.82 0.8 0.76 1"
          contype="0" conaffinity="0"/>
    <geom name="housing" type="box" size="{gw / 2 + 0.006} {gh / 2 + 0.006} 0.009" pos="0 0 -0.0115"
          rgba="0.12 0.12 0.13 1" contype="0" conaffinity="0"/>
    <body name="cam_target" pos="0 0 0.012"/>
    {frame_site}
    {_camera_xml(scene, (0.0, 0.0, 0.012))}
    <body name="gel_plate" pos="0 0 0" gravcomp="1">
      <joint name="gel_z" type="slide" axis="0 0 1" stiffness="{scene.gel_stiffness}"
             damping="10" range="-0.02 0.005" limited="false"/>
      <geom name="gel_pad" type="box" size="{gw / 2} {gh / 2} 0.0025" pos="0 0 -0.0025"
            mass="{scene.plate_mass}" rgba="0.55 0.6 0.62 1" condim="3" group="0"/>
      {sensor_site}
    </body>
    {_object_body_xml(scene, "0 0 0.05", 0.03)}
  </worldbody>
  {sensors}
</mujoco>"""


def scene_xml(scene: Scene) -> str:
    """The MJCF text of a validated press scene (only declared effects appear in it). The
    `grasp_lift` scene is the policy's: `tacgen_lib.policy.task.task_xml` builds its model."""
    if scene.kind != "press":
        raise ValueError(
            f"scene {scene.name!r}: kind {scene.kind!r} is built by the policy stage "
            "(tacgen_lib.policy.task.task_xml), not by compile_scene"
        )
    return _press_xml(scene)


def disable_undeclared(model: mujoco.MjModel, scene: Scene, *, sensors: bool) -> None:
    """Switch off in `model` the physics `scene` does not declare: gravity without
    ``gravity``, friction loss (and every geom's contact to one dimension) without
    ``friction_shear``, and MuJoCo's sensors unless `sensors`."""
    flags = 0
    if not scene.has("gravity"):
        flags |= mujoco.mjtDisableBit.mjDSBL_GRAVITY
    if not scene.has("friction_shear"):
        flags |= mujoco.mjtDisableBit.mjDSBL_FRICTIONLOSS
        model.geom_condim[:] = 1
    if not sensors:
        flags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    model.opt.disableflags = int(model.opt.disableflags) | int(flags)


def compile_scene(scene: Scene, xml: str | None = None) -> mujoco.MjModel:
    """Compile a validated scene to an MjModel with undeclared physics disabled.

    `xml` is the scene's MJCF text (default `scene_xml(scene)`); a caller that edits it (as
    benchmarks/bench_sim.py adds a camera) still gets the texture assets it names, the
    disabled physics and the shadows of the corpus's own model.
    """
    model = mujoco.MjModel.from_xml_string(
        scene_xml(scene) if xml is None else xml, texture_assets()
    )
    disable_undeclared(model, scene, sensors=scene.has("tactile"))
    if not scene.has("shadows"):
        model.light_castshadow[:] = 0
    return model
