"""Simulated corpora: schema, determinism, sharding, appearance control, null control."""

import copy

import numpy as np
import pandas as pd
import pytest
from sim_scenes import fast_scenes

from tacgen_lib.corpus.manifest import LABEL_COLUMNS
from tacgen_lib.corpus.sim import corpus, samples
from tacgen_lib.corpus.sim.scenes import validate_scene
from tacgen_lib.io.images import decode_png

SCENES = fast_scenes()
PAIRED = {
    "name": "p",
    "kind": "simulated",
    "design": "paired",
    "n": 10,
    "seed": 7,
    "scene": "paired_press",
    "sensors": 3,
    "presses": 4,
}
CONTROLLED = {
    "name": "c",
    "kind": "simulated",
    "design": "controlled",
    "n": 12,
    "seed": 11,
    "scene": "controlled_press",
    "sensors": 2,
    "presses": 3,
}
FLOATS = list(LABEL_COLUMNS)  # the manifest's numeric labels, every one a simulator output


@pytest.fixture(scope="module")
def paired():
    return corpus.simulate_shard(PAIRED, SCENES, 0, 1)


def test_columns_dtypes_and_labels(paired):
    assert list(paired.columns) == corpus.COLUMNS
    assert paired.sample_id.is_unique and paired.sample_id[3] == "p-000003"
    for col in FLOATS:
        assert paired[col].dtype == np.float64 and np.isfinite(paired[col]).all(), col
    assert paired.appearance_id.dtype == np.int64 and paired.scene_seed.dtype == np.int64
    assert set(paired.density) <= {500.0, 2000.0, 5000.0}
    assert set(paired.hardness) <= {"soft", "hard"}
    assert (paired.force_p05 <= paired.force_p50).all()
    assert (paired.force_p50 <= paired.force_p95).all()
    weight_plus_press = paired.mass * 9.81 + SCENES["paired_press"]["press"]["force"]
    np.testing.assert_allclose(paired.force_normal, weight_plus_press, rtol=0.01)
    assert decode_png(paired.rgb[0]).shape == (224, 224, 3)
    assert decode_png(paired.tactile[0]).shape == (120, 160, 3)
    assert paired.null_source.isna().all()
    row = paired.iloc[0]
    assert row.caption.endswith(f"{row.hardness} and {row.adjectives[4]}")
    assert row.stratum == f"{row['shape']}|{row.hardness}|{int(row.density)}"


def test_same_seed_is_byte_identical_and_shards_concatenate(paired):
    again = corpus.simulate_shard(PAIRED, SCENES, 0, 1)
    pd.testing.assert_frame_equal(paired, again)
    parts = [corpus.simulate_shard(PAIRED, SCENES, s, 3) for s in range(3)]
    merged = pd.concat(parts).sort_values("sample_id").reset_index(drop=True)
    pd.testing.assert_frame_equal(paired, merged)


def test_tactile_frames_sit_on_the_recorded_background(paired):
    bgs = corpus.sensor_backgrounds(PAIRED)
    assert list(bgs.columns) == ["sensor_id", "background", "corpus"] and len(bgs) == 3
    by_id = dict(zip(bgs.sensor_id, bgs.background, strict=True))
    for _, row in paired.iterrows():
        frame = decode_png(row.tactile).astype(float)
        diff = frame - decode_png(by_id[row.sensor_id]).astype(float)
        corner = diff[:6, :6]  # outside every imprint: background + sensor noise only
        assert abs(corner.mean()) < 1.5 and 1.0 < corner.std() < 3.0


def test_controlled_appearance_identical_across_densities():
    df = corpus.simulate_shard(CONTROLLED, SCENES, 0, 1)
    assert set(df.scale) <= {0.15, 0.20, 0.25}
    groups = df.groupby("appearance_id")
    assert groups.ngroups == 4
    for _, g in groups:
        assert sorted(g.density) == [500.0, 2000.0, 5000.0]
        assert g.rgb.nunique() == 1  # identical RGB bytes whatever the density
        assert g.tactile.nunique() == 3 and g["mass"].is_monotonic_increasing
        assert g["shape"].nunique() == 1 and g.scale.nunique() == 1


def test_null_sources_is_a_derangement():
    for n in (2, 3, 17, 500):
        perm = samples.null_sources(9, n)
        assert sorted(perm) == list(range(n)) and np.all(perm != np.arange(n))
    assert np.array_equal(samples.null_sources(9, 50), samples.null_sources(9, 50))


def imprint_energy(df, cfg):
    bgs = corpus.sensor_backgrounds(cfg)
    by_id = {
        s: decode_png(b).astype(float) for s, b in zip(bgs.sensor_id, bgs.background, strict=True)
    }
    return np.array(
        [
            np.abs(decode_png(t).astype(float) - by_id[s]).mean()
            for t, s in zip(df.tactile, df.sensor_id, strict=True)
        ]
    )


def test_null_tactile_carries_no_label_information():
    scenes = copy.deepcopy(SCENES)
    decl = scenes["paired_press"]
    decl["effects"] = [e for e in decl["effects"] if e not in ("rgb", "texture", "press_jitter")]
    decl["objects"] = {"shapes": ["sphere"]}  # one shape: imprint energy tracks weight
    n = 80
    cfg = dict(PAIRED, n=n, name="q", presses=1)
    real = corpus.simulate_shard(cfg, scenes, 0, 1)
    null = corpus.simulate_shard(dict(cfg, null=True, name="qn"), scenes, 0, 1)
    for col in ("mass", "force_normal", "density"):
        assert null[col].tolist() == real[col].tolist()  # same labels, swapped touch
    assert null.null_source.notna().all()
    src = null.null_source.str[-6:].astype(int).to_numpy()
    assert np.all(src != np.arange(n))
    bound = 3 / np.sqrt(n)
    r_real = np.corrcoef(imprint_energy(real, cfg), real["mass"])[0, 1]
    r_null = np.corrcoef(imprint_energy(null, dict(cfg, name="qn")), null["mass"])[0, 1]
    print(f"corr(imprint energy, mass): paired {r_real:.3f}, null {r_null:.3f} (bound {bound:.3f})")
    assert r_real > 0.5
    assert abs(r_null) < bound


def test_bad_corpus_configs_are_refused():
    with pytest.raises(ValueError, match=r"corpora\.\w+\.colour: unknown key"):
        corpus.simulate_shard(dict(PAIRED, colour=1), SCENES, 0, 1)
    with pytest.raises(ValueError, match="shard 2 not in"):
        corpus.simulate_shard(PAIRED, SCENES, 2, 2)
    with pytest.raises(ValueError, match="grasp_lift"):
        corpus.simulate_shard(dict(PAIRED, scene="grasp_lift"), SCENES, 0, 1)


def test_repeated_contacts_share_their_object_and_nothing_else():
    """contacts = 3: rows 3o..3o+2 are one object (shape, size, physics, appearance, the
    appearance_id o), each with its own presses, sensor and pixel noise; contacts = 1 draws
    exactly the single-contact corpus."""
    scene = validate_scene("paired_press", SCENES["paired_press"])
    cfg = samples.CorpusSettings.from_config(dict(PAIRED, n=9, contacts=3))
    specs = [samples.sample_spec(cfg, scene, i) for i in range(9)]
    for o in range(3):
        group = specs[3 * o : 3 * o + 3]
        assert {s.appearance_id for s in group} == {o}
        assert len({(s.obj.shape, s.obj.size, s.obj.density, s.obj.stiffness) for s in group}) == 1
        assert (
            len({(s.obj.friction, s.obj.yaw, s.colour, s.texture, s.hardness) for s in group}) == 1
        )
        assert len({s.pixel_seed for s in group}) == 3
        assert not np.array_equal(group[0].jitter, group[1].jitter)
    assert len({(s.obj.shape, s.obj.size) for s in specs[::3]}) == 3  # three objects
    single = samples.CorpusSettings.from_config(PAIRED)
    one = samples.CorpusSettings.from_config(dict(PAIRED, contacts=1))
    for i in range(4):
        a, b = samples.sample_spec(single, scene, i), samples.sample_spec(one, scene, i)
        assert (a.obj, a.appearance_id, a.sensor, a.pixel_seed) == (
            b.obj,
            b.appearance_id,
            b.sensor,
            b.pixel_seed,
        )
        assert a.appearance_id == i


def test_repeated_contacts_frames_and_labels(paired):
    frame = corpus.simulate_shard(dict(PAIRED, n=6, contacts=2), SCENES, 0, 1)
    assert frame["appearance_id"].tolist() == [0, 0, 1, 1, 2, 2]
    per_object = frame.groupby("appearance_id")
    assert (per_object["mass"].nunique() == 1).all()
    assert (per_object["stratum"].nunique() == 1).all()
    # the first contact of object 0 is sample 0 of the single-contact corpus, frames and all
    pd.testing.assert_series_equal(frame.iloc[0], paired.iloc[0], check_names=False)


def test_bad_contacts_are_refused():
    with pytest.raises(ValueError, match=r"corpora\.p\.n: n=10 is not a whole number of objects"):
        samples.CorpusSettings.from_config(dict(PAIRED, contacts=3))
    with pytest.raises(ValueError, match=r"corpora\.c\.contacts: key 'contacts' belongs to design"):
        samples.CorpusSettings.from_config(dict(CONTROLLED, contacts=2))
    with pytest.raises(ValueError, match=r"corpora\.p\.contacts must be an integer >= 1, got 0"):
        samples.CorpusSettings.from_config(dict(PAIRED, contacts=0))
