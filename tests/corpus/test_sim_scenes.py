"""Scenes declare effects; only declared effects are compiled, run and rendered."""

import copy

import mujoco
import numpy as np
import pytest
import yaml

from tacgen_lib.corpus.sim import corpus, physics, tactile
from tacgen_lib.corpus.sim.render import render_rgb
from tacgen_lib.corpus.sim.scenes import (
    EFFECTS,
    TEXTURE_FACE,
    TEXTURE_MARK,
    TEXTURES,
    compile_scene,
    texture_faces,
    validate_scene,
    validate_scenes,
)
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.policy.task import GraspTask, phase_scene

SCENES = yaml.safe_load(open("config/scenes.yaml"))
FAST = {"settle_steps": 60, "measure_steps": 5}


def scene_with(effects, base="paired_press"):
    decl = copy.deepcopy(SCENES[base])
    decl.update(FAST)
    decl["effects"] = list(effects)
    return decl


def run(effects, n=4, **extra):
    scenes = {"s": scene_with(effects)}
    cfg = {"name": "t", "design": "paired", "n": n, "seed": 3, "scene": "s", "presses": 3}
    cfg.update(extra)
    return corpus.simulate_shard(cfg, scenes, 0, 1)


def test_config_scenes_validate():
    scenes = validate_scenes(SCENES)
    assert {"paired_press", "controlled_press", "grasp_lift"} <= set(scenes)
    assert len(scenes["paired_press"].shapes) >= 4


@pytest.mark.parametrize(
    ("decl", "words"),
    [
        ({"effects": ["gravity", "smell"]}, ["'bad'", "'smell'"]),
        ({"effects": ["gravity"], "colour": 1}, ["'bad'", "'colour'"]),
        ({"effects": ["gravity"], "press": {"forse": 1}}, ["'bad'", "press.", "'forse'"]),
        ({"effects": ["gravity"], "objects": {"shapes": ["torus"]}}, ["'bad'", "'torus'"]),
        ({"effects": []}, ["'bad'", "'effects'"]),
    ],
)
def test_bad_declarations_name_scene_and_key(decl, words):
    with pytest.raises(ValueError) as err:
        validate_scene("bad", decl)
    for w in words:
        assert w in str(err.value)


def test_undeclared_physics_is_disabled_in_the_model():
    bare = compile_scene(validate_scene("bare", {"effects": ["tactile"]}))
    full = compile_scene(validate_scene("full", {"effects": list(EFFECTS)}))
    dis = mujoco.mjtDisableBit
    assert bare.opt.disableflags & dis.mjDSBL_GRAVITY
    assert bare.opt.disableflags & dis.mjDSBL_FRICTIONLOSS
    assert np.all(bare.geom_condim == 1)
    assert not full.opt.disableflags & (dis.mjDSBL_GRAVITY | dis.mjDSBL_FRICTIONLOSS)
    assert bare.ncam == 0 and full.ncam == 1  # no RGB camera without `rgb`
    assert bare.ntex == 0 and full.ntex > 0  # no textures without `texture`
    assert np.all(bare.light_castshadow == 0) and np.any(full.light_castshadow == 1)
    assert bare.vis.quality.shadowsize == 0
    no_touch = compile_scene(validate_scene("n", {"effects": ["gravity"]}))
    assert no_touch.nsensor == 0 and no_touch.nsite == 0  # no tactile sensor built
    assert no_touch.opt.disableflags & dis.mjDSBL_SENSOR


def test_without_rgb_no_renderer_is_created_and_no_frame_rendered(monkeypatch):
    calls = {"render": 0, "renderer": 0}
    real_render = render_rgb

    def spy_render(*a, **k):
        calls["render"] += 1
        return real_render(*a, **k)

    class SpyRenderer:
        def __init__(self, *a, **k):
            calls["renderer"] += 1
            raise AssertionError("Renderer created although `rgb` is not declared")

    monkeypatch.setattr(corpus, "render_rgb", spy_render)
    monkeypatch.setattr(mujoco, "Renderer", SpyRenderer)
    df = run(["gravity", "press", "tactile", "sensor_noise"])
    assert calls == {"render": 0, "renderer": 0}
    assert df["rgb"].isna().all() and df["tactile"].notna().all()


def test_without_tactile_or_noise_those_functions_never_run(monkeypatch):
    calls = {"rays": 0, "shade": 0, "noise": 0}
    for name in ("height_field_rays", "tactile_shading", "sensor_noise"):
        real = getattr(tactile, name)
        key = {"height_field_rays": "rays", "tactile_shading": "shade"}.get(name, "noise")

        def spy(*a, _real=real, _key=key, **k):
            calls[_key] += 1
            return _real(*a, **k)

        monkeypatch.setattr(tactile, name, spy)
    df = run(["gravity", "press"])
    assert calls == {"rays": 0, "shade": 0, "noise": 0} and df["tactile"].isna().all()
    run(["gravity", "press", "tactile"])
    assert calls["rays"] == 4 and calls["shade"] == 4 and calls["noise"] == 0
    run(["gravity", "press", "tactile", "sensor_noise"])
    assert calls["noise"] == 4


def test_without_press_jitter_one_press_per_sample(monkeypatch):
    calls = {"press": 0}
    real = physics.press_object

    def spy(*a, **k):
        calls["press"] += 1
        return real(*a, **k)

    monkeypatch.setattr(physics, "press_object", spy)
    df = run(["gravity", "press", "contact_compliance"])
    assert calls["press"] == 4
    assert (df.force_p05 == df.force_normal).all() and (df.force_p95 == df.force_normal).all()
    run(["gravity", "press", "contact_compliance", "press_jitter"])
    assert calls["press"] == 4 + 4 * (1 + 3)


def test_declared_effects_do_not_depend_on_unrelated_effects():
    base = [
        "gravity",
        "contact_compliance",
        "friction_shear",
        "press",
        "press_jitter",
        "tactile",
        "sensor_noise",
    ]
    a = run(base)
    b = run(base + ["rgb", "texture", "shadows"])
    assert a["rgb"].isna().all() and b["rgb"].notna().all()
    for col in ("tactile", "force_normal", "force_p05", "force_p95", "mass", "stiffness"):
        assert a[col].tolist() == b[col].tolist(), col
    c = run(["rgb", "texture"])
    d = run(["rgb", "texture", "gravity", "press", "tactile"])
    assert c["rgb"].tolist() == d["rgb"].tolist()  # the RGB frame ignores all physics


def test_a_second_sensor_differs_only_in_what_its_scene_declares():
    """gelsight_press (config/scenes.yaml) is paired_press's objects and press on another
    sensor: the same samples' objects, other tactile frames (its own size, markers, lights).
    (The context camera sees the other sensor's window too, so the RGB frames differ.)"""
    scenes = {
        name: {**copy.deepcopy(SCENES[name]), **FAST} for name in ("paired_press", "gelsight_press")
    }
    cfg = {"name": "t", "design": "paired", "n": 3, "seed": 3, "presses": 2}
    digit = corpus.simulate_shard({**cfg, "scene": "paired_press"}, scenes, 0, 1)
    gel = corpus.simulate_shard(
        {**cfg, "scene": "gelsight_press", "tactile_size": [96, 128]}, scenes, 0, 1
    )
    assert digit["shape"].tolist() == gel["shape"].tolist()
    assert digit["mass"].tolist() == gel["mass"].tolist()
    from tacgen_lib.io.images import decode_png

    a, b = decode_png(digit["tactile"].iloc[0]), decode_png(gel["tactile"].iloc[0])
    assert a.shape == (120, 160, 3) and b.shape == (96, 128, 3)
    # the markers: a 9-pixel periodic darkening of the GelSight-like frame's background rows
    row = b[2].astype(float).mean(axis=1)
    spectrum = np.abs(np.fft.rfft(row - row.mean()))
    assert np.argmax(spectrum[1:]) + 1 == round(128 / 9)


def test_each_texture_face_draws_its_caption_word():
    faces = texture_faces()
    assert sorted(faces) == sorted(t for t in TEXTURES if t != "plain")
    mark = TEXTURE_MARK
    for face in faces.values():
        assert face.shape == (TEXTURE_FACE, TEXTURE_FACE)
        assert set(np.unique(face)) == {mark, 1.0}
    striped = faces["striped"]
    assert (striped == striped[:, :1]).all()  # parallel bands: constant along one axis
    runs = np.count_nonzero(np.diff(striped[:, 0]))  # six bands, five edges between them
    assert runs == 5
    checker = faces["checkered"]
    half = TEXTURE_FACE // 2
    quads = [checker[:half, :half], checker[:half, half:], checker[half:, :half]]
    assert all(np.unique(q).size == 1 for q in quads)  # a 2 x 2 checkerboard
    assert quads[0][0, 0] != quads[1][0, 0] and quads[0][0, 0] != quads[2][0, 0]
    speck = faces["speckled"]
    assert 0.25 < np.mean(speck == mark) < 0.45  # the marks cover about 35 % of the face
    assert not (speck == speck[:, :1]).all()  # and make no bands
    assert np.array_equal(texture_faces()["speckled"], speck)  # seeded: the same every run


def test_the_textures_compile_into_the_corpus_scene_and_the_policy_task():
    full = compile_scene(validate_scene("full", {"effects": list(EFFECTS)}))
    names = {mujoco.mj_id2name(full, mujoco.mjtObj.mjOBJ_TEXTURE, i) for i in range(full.ntex)}
    assert names == {f"tex_{t}" for t in texture_faces()}
    decl = SCENES["grasp_lift"]
    grasp = GraspTask(phase_scene(decl, ["rgb", "texture"], 0.001), PolicySettings())
    assert grasp.model.ntex == full.ntex
    np.testing.assert_array_equal(grasp.model.tex_data, full.tex_data)
