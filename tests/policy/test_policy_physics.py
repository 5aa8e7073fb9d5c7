"""Physics sanity of the grasp-lift-hold task (tacgen_lib.policy.task / palpation / oracle).

The window's ends are checked on objects that are light or heavy, slippery or grippy, hard or
soft; the holding contact model's creep floor against the slip criterion; the phases' effects.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
import yaml

from tacgen_lib.corpus.sim import tactile
from tacgen_lib.corpus.splits import LeakageError
from tacgen_lib.policy import data, oracle, palpation, task
from tacgen_lib.policy.settings import PolicySettings

DECL = yaml.safe_load(open("config/scenes.yaml"))["grasp_lift"]
SETTINGS = PolicySettings()


@pytest.fixture(scope="module")
def lift() -> task.GraspTask:
    return data.compile_phase(DECL, SETTINGS, "lift")


def make_episode(density: float, friction: float, soft: bool, size: float = 0.05) -> task.Episode:
    """An object with a window: soft = the softest stiffness leaving a 2.5x window (crush just
    above the need), hard = 5000 N/m."""
    ep = task.Episode("t-0", size, (0.5, 0.5, 0.5, 1.0), "plain", density, friction, 1.0, 1.0)
    lo, _ = task.window(ep, SETTINGS)
    k = 2.5 * lo / SETTINGS.crush_depth if soft else 5000.0
    return dataclasses.replace(ep, stiffness=k, crush_limit=k * SETTINGS.crush_depth)


OBJECTS = {
    f"{w}-{f}-{h}": make_episode(dens, mu, h == "soft")
    for w, dens in (("light", 300.0), ("heavy", 2500.0))
    for f, mu in (("slippery", 0.3), ("grippy", 1.0))
    for h in ("hard", "soft")
}


@pytest.mark.parametrize("name", sorted(OBJECTS))
def test_window_ends_slip_and_crush(lift, name):
    ep = OBJECTS[name]
    lo, hi = task.window(ep, SETTINGS)
    below = task.rollout(lift, ep, 0.6 * lo)
    inside = task.rollout(lift, ep, np.sqrt(lo * hi))
    above = task.rollout(lift, ep, 1.3 * hi)
    assert below.mode in ("slip", "drop"), (name, below)
    assert inside.mode == "success", (name, inside)
    assert above.mode == "crush", (name, above)
    # no MuJoCo warnings in any of them (rollout raises on one); state is clean
    assert all(w.number == 0 for w in lift.data.warning)


def test_oracle_succeeds_on_held_out_episodes(lift):
    eps = task.sample_episodes(SETTINGS, data.set_seed(SETTINGS, "heldout"), 60, "held")
    modes = [task.rollout(lift, ep, oracle.oracle_force(ep, SETTINGS)).mode for ep in eps]
    assert np.mean([m == "success" for m in modes]) >= 0.95, modes


def test_halving_the_timestep_keeps_the_oracle_outcomes():
    eps = task.sample_episodes(SETTINGS, 99, 12, "dt")
    outcomes = []
    for dt in (SETTINGS.timestep, SETTINGS.timestep / 2):
        s = dataclasses.replace(SETTINGS, timestep=dt)
        t = data.compile_phase(DECL, s, "lift")
        outcomes.append([task.rollout(t, ep, oracle.oracle_force(ep, s)) for ep in eps])
    assert [o.mode for o in outcomes[0]] == [o.mode for o in outcomes[1]]
    # and the measured quantities agree closely (rise within 0.5 mm, peak force within 15 %)
    for a, b in zip(*outcomes, strict=True):
        assert abs(a.lift - b.lift) < 5e-4
        assert b.peak_force == pytest.approx(a.peak_force, rel=0.15)


def test_below_window_at_halved_timestep_still_fails():
    s = dataclasses.replace(SETTINGS, timestep=SETTINGS.timestep / 2)
    t = data.compile_phase(DECL, s, "lift")
    ep = OBJECTS["heavy-slippery-hard"]
    lo, hi = task.window(ep, s)
    assert task.rollout(t, ep, 0.6 * lo).mode in ("slip", "drop")
    assert task.rollout(t, ep, 1.3 * hi).mode == "crush"


def test_creep_floor_far_below_slip_criterion(lift):
    """google-deepmind/mujoco#3328: a held object creeps under gravity with soft friction;
    noslip iterations cut it. The floor (with the holding contact model) must sit far below
    the slip criterion's rate, and noslip must matter."""
    ep = OBJECTS["heavy-slippery-hard"]
    f = oracle.oracle_force(ep, SETTINGS)
    floor = task.creep_floor(lift, ep, f, hold_time=1.5)
    no_noslip = data.compile_phase(DECL, dataclasses.replace(SETTINGS, noslip_iterations=0), "lift")
    without = task.creep_floor(no_noslip, ep, f, hold_time=1.5)
    criterion = SETTINGS.slip_limit / (SETTINGS.hold_time - task.HOLD_SETTLE)
    print(
        f"creep floor {floor * 1e6:.1f} um/s (no noslip: {without * 1e6:.1f} um/s), "
        f"slip criterion {criterion * 1e6:.0f} um/s"
    )
    assert floor * 20 < criterion
    assert without > 3 * floor


def test_rollouts_and_palpation_are_byte_identical(lift):
    ep = task.sample_episode(SETTINGS, 5, 3, "rep")
    a = task.rollout(lift, ep, 1.234)
    b = task.rollout(lift, ep, 1.234)
    assert a == b
    palp = data.compile_phase(DECL, SETTINGS, "palpation")
    optics = palpation.PadOptics(SETTINGS.tactile_size)
    p = palpation.palpate(palp, ep, optics, noise_seed=11)
    q = palpation.palpate(palp, ep, optics, noise_seed=11)
    assert p.rgb.tobytes() == q.rgb.tobytes()
    assert list(p.frames) == list(q.frames)
    assert all(p.frames[k].tobytes() == q.frames[k].tobytes() for k in p.frames)


def test_lift_never_runs_an_undeclared_pass(lift, monkeypatch):
    """The lift declares physics only: no camera, no texture, no tactile pass is ever called."""
    assert lift.model.ncam == 0 and lift.model.ntex == 0 and lift.model.nsite == 0
    calls = []

    def spy(name):
        def f(*a, **k):
            calls.append(name)
            raise AssertionError(f"{name} called during a physics-only phase")

        return f

    monkeypatch.setattr(tactile, "height_field_rays", spy("height_field_rays"))
    monkeypatch.setattr(tactile, "tactile_shading", spy("tactile_shading"))
    monkeypatch.setattr(mujoco, "Renderer", spy("Renderer"))
    ep = OBJECTS["light-grippy-hard"]
    task.rollout(lift, ep, oracle.oracle_force(ep, SETTINGS))
    # palpating on a task compiled without rgb/tactile also renders nothing
    obs = palpation.palpate(lift, ep, palpation.PadOptics((16, 16)), noise_seed=0)
    assert obs.rgb is None and obs.frames == {} and calls == []


def test_palpation_sees_compliance_and_weight():
    """The same squeeze indents a soft object further; a heavy slippery one is not hefted."""
    palp = data.compile_phase(DECL, SETTINGS, "palpation")
    optics = palpation.PadOptics(SETTINGS.tactile_size)
    soft = make_episode(300.0, 1.0, soft=True)
    hard = dataclasses.replace(soft, stiffness=5000.0, crush_limit=20.0)
    heavy = OBJECTS["heavy-slippery-hard"]

    def imprint(ep, name="tactile_squeeze_1_left_pad"):
        obs = palpation.palpate(palp, ep, optics, noise_seed=0)
        bg = palpation.pad_background(SETTINGS.seed, 0, SETTINGS.tactile_size)
        return np.abs(obs.frames[name].astype(int) - bg).sum(), obs.held

    (soft_sig, _), (hard_sig, light_held), (_, heavy_held) = map(imprint, (soft, hard, heavy))
    assert soft_sig > 1.5 * hard_sig
    assert light_held == (True, True) and heavy_held == (False, False)


def test_appearance_is_independent_of_physics():
    narrow = dataclasses.replace(SETTINGS, density_range=(1000.0, 1000.0))
    a = task.sample_episode(SETTINGS, 3, 7)
    b = task.sample_episode(narrow, 3, 7)
    assert (a.size, a.rgba, a.texture) == (b.size, b.rgba, b.texture)
    assert a.density != b.density


def test_phase_cannot_declare_an_effect_the_scene_lacks():
    with pytest.raises(ValueError, match="not declared by scene 'grasp_lift'"):
        task.phase_scene(dict(DECL, effects=["gravity"]), ["gravity", "tactile"], 0.001)


def test_training_refuses_held_out_episodes():
    frame = data.collect_episodes(
        dataclasses.replace(PolicySettings.tiny(), n_demos=4, n_heldout=4), DECL, "heldout", 0, 1
    )
    with pytest.raises(LeakageError, match="held-out"):
        data.training_rows(frame, frame["episode_id"], rule="train_policy")


def test_vision_ceiling_force_maximises_expected_success():
    s = SETTINGS
    f = oracle.vision_ceiling_force(s, 0.05, seed=1)
    lo, hi = oracle.invisible_prior(s, 0.05, 4000, seed=2)  # fresh draws

    def p(x):
        return np.mean((lo <= x) & (x <= hi))

    assert p(f) >= max(p(0.7 * f), p(1.4 * f)) - 0.02
    assert p(f) < 0.8  # size alone cannot find the window: touch is needed
