"""MuJoCo press physics: force = weight (+ press), stability, timestep, monotone imprints."""

import copy

import numpy as np
import pytest
import yaml
from sim_scenes import gel_heights

from tacgen_lib.corpus.sim import physics, tactile
from tacgen_lib.corpus.sim.scenes import SHAPES, compile_scene, validate_scene

SCENES = yaml.safe_load(open("config/scenes.yaml"))
FORCE_TOL = 0.005  # relative: resting force vs m g
DT_TOL = 0.005  # relative: force change when the timestep is halved


def runtime(effects, **over):
    decl = copy.deepcopy(SCENES["paired_press"])
    decl["effects"] = effects
    decl.update(over)
    scene = validate_scene("t", decl)
    return physics.SceneRuntime(scene, compile_scene(scene))


def imprint(rt, press_force):
    res = physics.press_object(rt, press_force)
    optics = tactile.GelOptics(rt.scene.gel_size, (120, 160), 0.05, 0.002, 0.0006)
    raw = gel_heights(rt, optics)
    return res, np.minimum(raw, res.gel_depth)


# (shape, size m, density kg/m^3, stiffness N/m): light, heavy, stiff, soft and tiny cases.
CASES = [
    ("cube", 0.02, 500, 600),
    ("cube", 0.04, 5000, 25000),
    ("sphere", 0.02, 500, 25000),
    ("sphere", 0.04, 5000, 600),
    ("cylinder", 0.03, 2000, 8000),
    ("capsule", 0.02, 500, 25000),
    ("ellipsoid", 0.02, 500, 2000),
    ("cube", 0.005, 500, 25000),
    ("sphere", 0.04, 20000, 25000),
]


@pytest.mark.parametrize(("shape", "size", "density", "stiffness"), CASES)
def test_resting_force_is_weight_stable_and_finite(shape, size, density, stiffness):
    rt = runtime(["gravity", "contact_compliance", "friction_shear", "tactile"])
    obj = physics.ObjectPhysics(shape, size, density, stiffness, 0.8, 0.3)
    physics.apply_object(rt, obj)
    res = physics.press_object(rt, 0.0)  # raises PhysicsWarning on any MuJoCo warning
    weight = obj.mass * physics.GRAVITY
    assert np.isfinite(rt.data.qpos).all() and np.isfinite(res.force_normal)
    assert res.force_normal == pytest.approx(weight, rel=FORCE_TOL)
    assert res.gel_depth == pytest.approx(weight / rt.scene.gel_stiffness, rel=0.02)


def test_press_adds_to_weight_and_halving_timestep_keeps_force():
    rel = []
    for shape in SHAPES:
        obj = physics.ObjectPhysics(shape, 0.03, 2000, 5000, 0.8, 0.2)
        forces = []
        for dt, steps in ((5e-4, 120), (2.5e-4, 240)):
            rt = runtime(
                ["gravity", "contact_compliance", "press"], timestep=dt, settle_steps=steps
            )
            physics.apply_object(rt, obj)
            forces.append(physics.press_object(rt, 0.5).force_normal)
        assert forces[0] == pytest.approx(obj.mass * physics.GRAVITY + 0.5, rel=FORCE_TOL)
        rel.append(abs(forces[1] / forces[0] - 1))
    print(f"max relative force change when halving the timestep: {max(rel):.2e} (tol {DT_TOL})")
    assert max(rel) < DT_TOL


@pytest.mark.parametrize("shape", ["sphere", "cube", "capsule"])
def test_imprint_grows_with_mass_under_gravity(shape):
    rt = runtime(["gravity", "contact_compliance"])
    depth, area, volume = [], [], []
    for density in (500, 2000, 5000, 20000):
        physics.apply_object(rt, physics.ObjectPhysics(shape, 0.03, density, 20000, 0.8))
        res, h = imprint(rt, 0.0)
        depth.append(res.gel_depth)
        area.append(int((h > 0).sum()))
        volume.append(float(h.sum()))
    assert np.all(np.diff(depth) > 0) and np.all(np.diff(volume) > 0)
    assert np.all(np.diff(area) >= 0) and area[-1] > area[0]


@pytest.mark.parametrize("shape", ["sphere", "cube", "cylinder"])
def test_imprint_spreads_with_compliance_under_fixed_press(shape):
    rt = runtime(["gravity", "contact_compliance", "press"])
    area, approach = [], []
    for stiffness in (25000, 8000, 2000, 600):  # increasing compliance
        physics.apply_object(rt, physics.ObjectPhysics(shape, 0.03, 2000, stiffness, 0.8))
        res, h = imprint(rt, 0.5)
        area.append(int((h > 0).sum()))
        approach.append(res.approach)
    assert np.all(np.diff(approach) > 0)
    assert np.all(np.diff(area) >= 0) and area[-1] > area[0]
