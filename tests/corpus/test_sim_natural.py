"""The natural design: material classes with within-class spread, an appearance class linked to
the material by rho (exactly at rho = 0 and 1), appearance families that neither colour nor
texture decodes alone, physics that does not depend on rho, and the simulator end to end."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats
from sim_scenes import fast_scenes

from tacgen_lib.corpus.looks import PALETTE, TEXTURE_WORDS
from tacgen_lib.corpus.sim import corpus, samples
from tacgen_lib.corpus.sim.physics import shape_volume
from tacgen_lib.corpus.sim.scenes import validate_scene

SCENES = fast_scenes()
NATURAL = {
    "name": "nat",
    "kind": "simulated",
    "design": "natural",
    "n": 12,
    "seed": 5,
    "scene": "paired_press",
    "sensors": 2,
    "presses": 3,
    "rho": 0.5,
}
N_CLASSES = len(samples.MATERIALS)


def specs(rho: float, n: int = 900) -> list[samples.SampleSpec]:
    cfg = samples.CorpusSettings.from_config(dict(NATURAL, rho=rho, n=n))
    scene = validate_scene(cfg.scene, SCENES[cfg.scene])
    return [samples.sample_spec(cfg, scene, i) for i in range(n)]


def material_index(spec: samples.SampleSpec) -> int:
    return [m.name for m in samples.MATERIALS].index(spec.material)


def test_rho_one_shows_the_material_and_rho_zero_is_independent_of_it():
    assert all(s.appearance_id == material_index(s) for s in specs(1.0))
    zero = specs(0.0)
    table = np.zeros((N_CLASSES, N_CLASSES))
    for s in zero:
        table[material_index(s), s.appearance_id] += 1
    # independence of material and appearance class (chi-square test of the 6 x 6 table)
    assert stats.chi2_contingency(table).pvalue > 0.001
    match = np.mean([s.appearance_id == material_index(s) for s in zero])
    assert abs(match - 1 / N_CLASSES) < 4 * np.sqrt((1 / 6) * (5 / 6) / len(zero))


@pytest.mark.parametrize("rho", [0.25, 0.5, 0.8])
def test_the_match_rate_is_rho_plus_chance(rho):
    got = specs(rho)
    match = np.mean([s.appearance_id == material_index(s) for s in got])
    want = rho + (1 - rho) / N_CLASSES
    assert abs(match - want) < 4 * np.sqrt(want * (1 - want) / len(got))


def test_physics_and_geometry_do_not_depend_on_rho():
    """A rho grid changes only what the objects look like: material, density, stiffness,
    friction, shape, size, presses and sensor of every sample are the same at every rho."""
    a, b = specs(0.0, 200), specs(1.0, 200)
    for x, y in zip(a, b, strict=True):
        assert x.obj == dataclasses.replace(y.obj, yaw=x.obj.yaw)
        assert (x.material, x.hardness, x.sensor, x.pixel_seed) == (
            y.material,
            y.hardness,
            y.sensor,
            y.pixel_seed,
        )
        np.testing.assert_array_equal(x.jitter, y.jitter)


def test_materials_set_hardness_and_spread_within_class():
    got = specs(0.5)
    for mat in samples.MATERIALS:
        mine = [s for s in got if s.material == mat.name]
        assert len(mine) > 100
        assert {s.hardness for s in mine} == {mat.hardness}
        k = np.array([s.obj.stiffness for s in mine])
        assert (k >= mat.stiffness[0]).all() and (k <= mat.stiffness[1]).all()
        log_d = np.log([s.obj.density for s in mine])
        # log-normal spread around the class density: mean and sd within sampling error
        assert abs(log_d.mean() - np.log(mat.density)) < 4 * samples.DENSITY_LOG_SD / np.sqrt(
            len(mine)
        )
        assert 0.8 < log_d.std(ddof=1) / samples.DENSITY_LOG_SD < 1.2
    assert {m.hardness for m in samples.MATERIALS} == {"soft", "hard"}


def test_neither_colour_nor_texture_alone_names_the_appearance_class():
    families = samples.APPEARANCE_FAMILIES
    assert len(families) == N_CLASSES
    pairs = [p for fam in families for p in fam]
    assert len(pairs) == len(set(pairs)) == len(PALETTE) * len(TEXTURE_WORDS)
    for texture in TEXTURE_WORDS:  # every texture occurs in every class
        assert sum(any(t == texture for _c, t in fam) for fam in families) == N_CLASSES
    for colour in PALETTE:  # every colour in as many classes as there are textures
        classes = [c for c, fam in enumerate(families) if any(k == colour for k, _t in fam)]
        assert len(classes) == len(TEXTURE_WORDS)
    # the appearance drawn is a member of its class's family, its colour jittered
    for s in specs(0.5, 100):
        assert (s.colour, s.texture) in families[s.appearance_id]
        assert s.rgb is not None and s.rgb != PALETTE[s.colour]


def test_appearance_class_is_the_material_below_rho_else_the_uniform_draw():
    assert samples.appearance_class(3, 0.0, 0.0, 5) == 5  # rho = 0: never the material
    assert samples.appearance_class(3, 1.0, 0.999999, 5) == 3  # rho = 1: always
    assert samples.appearance_class(3, 0.5, 0.49, 5) == 3
    assert samples.appearance_class(3, 0.5, 0.5, 5) == 5


def test_natural_corpus_simulates_and_records_material_and_appearance():
    df = corpus.simulate_shard(NATURAL, SCENES, 0, 1)
    assert list(df.columns) == corpus.COLUMNS and len(df) == 12
    materials = {m.name: m for m in samples.MATERIALS}
    for r in df.itertuples():
        material, appearance = r.stratum.split("|appearance~")
        assert int(appearance) == r.appearance_id
        assert r.hardness == materials[material].hardness
        assert r.mass == pytest.approx(r.density * shape_volume(r.shape, r.scale), rel=1e-9)
    assert np.isfinite(df[["force_normal", "force_p50", "mass"]]).all().all()
    again = corpus.simulate_shard(NATURAL, SCENES, 0, 1)
    assert df.equals(again)


def test_rho_outside_the_natural_design_or_the_unit_interval_is_refused():
    with pytest.raises(
        ValueError, match=r"corpora\.nat\.rho must be a finite number >= 0 and <= 1, got 1\.5"
    ):
        samples.CorpusSettings.from_config(dict(NATURAL, rho=1.5))
    with pytest.raises(ValueError, match="'rho' belongs to design 'natural', not 'paired'"):
        samples.CorpusSettings.from_config(dict(NATURAL, design="paired"))


def test_a_rho_grid_simulated_together_equals_each_corpus_alone():
    # one press per sample for the whole grid: every frame and label as simulated alone
    grid = [dict(NATURAL, name=f"nat{k}", rho=rho) for k, rho in enumerate((0.0, 0.5, 1.0))]
    together = corpus.simulate_shards(grid, SCENES, 1, 2)
    assert len(together) == 3
    for cfg, got in zip(grid, together, strict=True):
        alone = corpus.simulate_shard(cfg, SCENES, 1, 2)
        assert got.equals(alone), cfg["name"]
    # the touch is the same at every rho, the appearance is not
    assert together[0]["tactile"].tolist() == together[2]["tactile"].tolist()
    assert together[0]["rgb"].tolist() != together[2]["rgb"].tolist()
    # rho = 0.5 draws each appearance class as rho = 0 or rho = 1 does: each frame is one of theirs
    for k, frame in enumerate(together[1]["rgb"]):
        assert frame in (together[0]["rgb"].iloc[k], together[2]["rgb"].iloc[k])


def test_a_grid_of_corpora_with_different_physics_is_refused():
    with pytest.raises(ValueError, match="'b' differs from 'a' in more than its name and rho"):
        corpus.simulate_shards(
            [dict(NATURAL, name="a"), dict(NATURAL, name="b", seed=6)], SCENES, 0, 1
        )
    with pytest.raises(ValueError, match="named twice"):
        corpus.simulate_shards([NATURAL, NATURAL], SCENES, 0, 1)
