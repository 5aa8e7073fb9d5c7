"""Simulated corpora (paired, appearance-controlled, natural, null), one shard at a time: each
sample's draws (`tacgen_lib.corpus.sim.samples`: a corpus's settings and designs) pressed in
MuJoCo, its frames rendered, its row of labels written (`COLUMNS`).

Labels: mass = density x MuJoCo geom volume; force_normal = MuJoCo contact force in the
nominal press; force_p05/p50/p95 = percentiles over `presses` repeated presses with seeded
jitter of the press force (x(1 + jitter_force N(0,1))), placement (N(0, jitter_xy) m) and yaw;
hardness = the contact-compliance class, stiffness = its effective contact stiffness (N/m).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.corpus.looks import PALETTE, TEXTURE_WORDS
from tacgen_lib.corpus.manifest import FORCE_COLUMNS, FRAME_COLUMNS, LABEL_COLUMNS
from tacgen_lib.corpus.sim import physics
from tacgen_lib.corpus.sim.render import (
    render_rgb,
    scene_runtime,
    sensor_background,
    sensor_id,
    tactile_frame,
)
from tacgen_lib.corpus.sim.samples import CorpusSettings, SampleSpec, null_sources, sample_spec
from tacgen_lib.corpus.sim.scenes import Scene, validate_scene
from tacgen_lib.io.images import encode_png

COLUMNS = [
    *FRAME_COLUMNS,
    "shape",
    "scale",
    "density",
    "mass",
    "hardness",
    "stiffness",
    "friction",
    *FORCE_COLUMNS,
    "appearance_id",
    "scene_seed",
    "stratum",
    "null_source",
    "mass_source",
    "force_source",
    "hardness_source",
]


def _settings(corpus: CorpusSettings | Mapping[str, Any]) -> CorpusSettings:
    return corpus if isinstance(corpus, CorpusSettings) else CorpusSettings.from_config(corpus)


def _adjectives(spec: SampleSpec, cfg: CorpusSettings) -> list[str]:
    if cfg.design in ("paired", "natural"):
        lo, hi = (float(v) for v in cfg.size_range)
        t = (spec.obj.size - lo) / (hi - lo)
    else:
        scales = sorted(float(s) for s in cfg.scales)
        t = scales.index(spec.scale) / max(len(scales) - 1, 1)
    size = "small" if t < 1 / 3 else ("medium-sized" if t < 2 / 3 else "large")
    mass = spec.obj.mass
    weight = "light" if mass < 0.02 else ("moderately heavy" if mass < 0.1 else "heavy")
    return [size, spec.colour, TEXTURE_WORDS[spec.texture], spec.hardness, weight]


def simulate_shard(
    corpus: CorpusSettings | Mapping[str, Any],
    scenes: dict,
    shard: int,
    n_shards: int,
    progress: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Simulate the samples i of `corpus` with i % n_shards == shard (columns: `COLUMNS`).

    corpus: its settings, or its config mapping (`CorpusSettings.from_config`). scenes: the scenes.yaml mapping (scene name -> declaration). Raises ValueError for bad
    configs and physics.PhysicsWarning if MuJoCo warns during any press.
    """
    return simulate_shards([corpus], scenes, shard, n_shards, progress)[0]


def appearance_grid_key(cfg: CorpusSettings) -> CorpusSettings:
    """What corpora of one appearance grid share: the settings but the name and rho. Corpora
    with equal keys draw the same physics for every sample (rho changes only the appearance
    class, `samples._natural_spec`) and so press the same objects into the same touch."""
    return replace(cfg, name="", rho=0.0)


def _grid_settings(corpora: Sequence[CorpusSettings | Mapping[str, Any]]) -> list[CorpusSettings]:
    """The settings of corpora `simulate_shards` may simulate at once: at least one, each
    named once, all differing only in name and rho (`appearance_grid_key`); else ValueError."""
    cfgs = [_settings(c) for c in corpora]
    if not cfgs:
        raise ValueError("simulate_shards: no corpus to simulate")
    names = [str(c.name) for c in cfgs]
    if len(set(names)) != len(names):
        raise ValueError(f"simulate_shards: a corpus is named twice in {names}")
    for other in cfgs[1:]:
        if appearance_grid_key(other) != appearance_grid_key(cfgs[0]):
            raise ValueError(
                f"simulate_shards: corpus {other.name!r} differs from {cfgs[0].name!r} in more "
                "than its name and rho, so their physics differ; simulate them one at a time"
            )
    return cfgs


def simulate_shards(
    corpora: Sequence[CorpusSettings | Mapping[str, Any]],
    scenes: dict,
    shard: int,
    n_shards: int,
    progress: Callable[[str], None] | None = None,
) -> list[pd.DataFrame]:
    """`simulate_shard` of several corpora that differ only in name and rho (the natural
    design's rho grid, `appearance_grid_key`) at once: each sample's physics and touch are
    simulated once and its RGB frame rendered once per distinct look (object, colour,
    texture, size) among the corpora. Every frame is the one `simulate_shard` gives that
    corpus alone (the presses do not read the appearance, and a render only reads the look and
    the presentation pose): one MuJoCo press instead of one per corpus, and at most two
    renders per sample on a rho grid (its appearance class is the material's or the uniform
    draw, `samples._natural_spec`).

    Raises ValueError if the corpora differ in anything else or name a corpus twice.
    """
    cfgs = _grid_settings(corpora)
    names = [str(c.name) for c in cfgs]
    cfg = cfgs[0]
    if not 0 <= shard < n_shards:
        raise ValueError(f"corpus {cfg.name!r}: shard {shard} not in [0, {n_shards})")
    if cfg.scene not in scenes:
        raise ValueError(f"corpus {cfg.name!r}: scene {cfg.scene!r} not in scenes file")
    scene = validate_scene(cfg.scene, scenes[cfg.scene])
    if scene.kind != "press":
        raise ValueError(
            f"corpus {cfg.name!r}: scene {scene.name!r} is a {scene.kind!r} scene; corpora "
            "need a 'press' scene"
        )
    state = scene_runtime(scene, cfg)
    rt: physics.SceneRuntime = state["rt"]
    n, label = int(cfg.n), ", ".join(names)
    perm = null_sources(int(cfg.seed), n) if cfg.null else None
    press_force = scene.press_force
    rows: list[list[dict]] = [[] for _ in cfgs]
    t0 = time.perf_counter()
    indices = range(shard, n, n_shards)
    for count, i in enumerate(indices):
        specs = [sample_spec(c, scene, i) for c in cfgs]
        rgbs: list[bytes | None] = []
        # each corpus's look, then one press: the last look applied stays, which no press
        # reads. A frame reads only the object, its look and the presentation pose, so a look
        # another corpus of the grid already rendered for this sample is that frame (a rho
        # grid's sample has at most two looks: `samples._natural_spec` couples the draws)
        looks: list[tuple] = []
        for c, spec in zip(cfgs, specs, strict=True):
            rgba = (*(spec.rgb or PALETTE[spec.colour]), 1.0)
            look = (spec.obj, rgba, spec.texture, tuple(c.image_size))
            if look in looks:
                rgb = rgbs[looks.index(look)]
            else:
                physics.apply_object(rt, spec.obj, rgba=rgba, texture=spec.texture)
                rgb = None
                if scene.has("rgb"):
                    physics.presentation_pose(rt)
                    rgb = encode_png(
                        render_rgb(state, c.image_size), compression=int(cfg.png_compression)
                    )
            rgbs.append(rgb)
            looks.append(look)
        spec = specs[-1]
        tac, null_source = None, None
        if scene.has("tactile") and perm is None:
            tac, res = tactile_frame(state, spec, spec, cfg, press_force)
        else:
            res = physics.press_object(rt, press_force)
        forces = np.array([res.force_normal])
        if scene.has("press_jitter"):
            short = max(scene.settle_steps // 2, scene.measure_steps)
            forces = np.array(
                [
                    physics.press_object(
                        rt, press_force * jf, offset_xy=(dx, dy), dyaw=dyaw, settle_steps=short
                    ).force_normal
                    for jf, dx, dy, dyaw in spec.jitter
                ]
            )
        if perm is not None and scene.has("tactile"):
            j = int(perm[i])
            other = sample_spec(cfg, scene, j)
            physics.apply_object(rt, other.obj)
            tac, _ = tactile_frame(state, other, spec, cfg, press_force)
            null_source = j
        for k, (c, spec_c) in enumerate(zip(cfgs, specs, strict=True)):
            rows[k].append(_sample_row(c, scene, spec_c, rgbs[k], tac, res, forces, i, null_source))
        if progress is not None and (count + 1) % 50 == 0:
            dt = time.perf_counter() - t0
            progress(
                f"{label} shard {shard}/{n_shards}: {count + 1} samples, "
                f"{1e3 * dt / (count + 1):.1f} ms/sample"
            )
    return [_frame(r) for r in rows]


def _sample_row(
    cfg: CorpusSettings,
    scene: Scene,
    spec: SampleSpec,
    rgb: bytes | None,
    tac: bytes | None,
    res: physics.PressResult,
    forces: np.ndarray,
    i: int,
    null_source: int | None,
) -> dict:
    """The corpus row of sample i (`COLUMNS`) from its draws, frames and presses."""
    name = str(cfg.name)
    p05, p50, p95 = np.percentile(forces, [5, 50, 95])
    adjectives = _adjectives(spec, cfg)
    shape_word = spec.obj.shape
    return {
        "sample_id": f"{name}-{i:06d}",
        "corpus": name,
        "rgb": rgb,
        "tactile": tac,
        "sensor_id": sensor_id(cfg, spec.sensor),
        "caption": f"a {adjectives[0]} {adjectives[1]} {adjectives[2]} {shape_word}, "
        f"{adjectives[3]} and {adjectives[4]}",
        "adjectives": adjectives,
        "shape": shape_word,
        "scale": float(spec.scale),
        "density": float(spec.obj.density),
        "mass": float(spec.obj.mass),
        "hardness": spec.hardness,
        "stiffness": float(res.stiffness),
        "friction": float(spec.obj.friction),
        "force_normal": float(res.force_normal),
        "force_p05": float(p05),
        "force_p50": float(p50),
        "force_p95": float(p95),
        "appearance_id": int(spec.appearance_id),
        "scene_seed": int(spec.scene_seed),
        # natural: the material and appearance classes (the regime's known process)
        "stratum": (
            f"{spec.material}|appearance~{spec.appearance_id}"
            if cfg.design == "natural"
            else f"{shape_word}|{spec.hardness}|{int(spec.obj.density)}"
        ),
        "null_source": None if null_source is None else f"{name}-{null_source:06d}",
        "mass_source": "density x MuJoCo geom volume (body_mass), kg",
        "force_source": (
            "MuJoCo normal contact force object-gel (mj_contactForce), nominal press; "
            f"bands over {len(forces)} jittered presses, N"
        ),
        "hardness_source": (
            "contact-compliance class; stiffness = effective contact stiffness from solref (N/m)"
            if scene.has("contact_compliance")
            else "not simulated (contact_compliance not declared): rigid contact"
        ),
    }


def _frame(rows: list[dict]) -> pd.DataFrame:
    df = pd.DataFrame(rows, columns=COLUMNS)
    for col in LABEL_COLUMNS:
        df[col] = df[col].astype("float64")
    for col in ("appearance_id", "scene_seed"):
        df[col] = df[col].astype("int64")
    return df


def sensor_backgrounds(corpus: CorpusSettings | Mapping[str, Any]) -> pd.DataFrame:
    """The exact background (PNG) each sensor's frames were built on: sensor_id, background,
    corpus."""
    cfg = _settings(corpus)
    return pd.DataFrame(
        {
            "sensor_id": [sensor_id(cfg, k) for k in range(int(cfg.sensors))],
            "background": [encode_png(sensor_background(cfg, k)) for k in range(int(cfg.sensors))],
            "corpus": [str(cfg.name)] * int(cfg.sensors),
        }
    )
