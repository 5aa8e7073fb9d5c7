"""Fixed splits and the split guard."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tacgen_lib.corpus.manifest import fuse_manifest
from tacgen_lib.corpus.splits import (
    LeakageError,
    SplitSettings,
    assert_trainable,
    ids_in_split,
    make_splits,
    split_size,
)

#: the embedded default's shares (config/config.yaml splits.fractions)
FRACTIONS = {"train": 0.7, "val": 0.1, "test": 0.2}


def _settings(seed: int = 42, **keys) -> SplitSettings:
    """Config splits at `seed` with the embedded default's fractions, and `keys` (by_scale,
    by_object: a corpus's shares, its mass classes 3 unless given)."""
    by_object = {c: {"classes": 3, **r} for c, r in keys.pop("by_object", {}).items()}
    return SplitSettings(
        seed=seed, fractions=FRACTIONS, by_scale=keys.pop("by_scale", {}), by_object=by_object
    )


def _manifest(n: int = 200) -> pd.DataFrame:
    rng = np.random.default_rng(3)
    strata = rng.choice(
        ["cube|hard", "sphere|soft", "cyl|hard", "box|soft"], n, p=[0.4, 0.3, 0.2, 0.1]
    )
    return pd.DataFrame(
        {
            "sample_id": [f"a-{i:05d}" for i in range(n)],
            "corpus": "a",
            "stratum": strata,
            "scale": np.nan,
        }
    )


def test_stratified_split_is_fixed_and_proportional():
    m = _manifest()
    s1 = make_splits(m, _settings(seed=42))
    s2 = make_splits(
        m.sample(frac=1.0, random_state=1), _settings(seed=42)
    )  # input order does not matter
    pd.testing.assert_frame_equal(s1, s2)
    assert s1["split"].value_counts().to_dict() == {"train": 140, "val": 20, "test": 40}
    merged = s1.merge(m, on="sample_id")
    share = merged.groupby("stratum")["split"].apply(lambda s: (s == "test").mean())
    assert share.between(0.15, 0.25).all(), share  # every stratum is represented in test
    assert not make_splits(m, _settings(seed=7))["split"].equals(s1["split"])


@pytest.mark.parametrize("n", [7, 60, 200, 1801])
def test_split_size_is_the_count_make_splits_draws(n):
    """The regime's parse-time size check reads the test count from split_size."""
    counts = make_splits(_manifest(n), _settings(seed=42))["split"].value_counts()
    assert counts["test"] == split_size(n, 0.2) and counts["val"] == split_size(n, 0.1)
    assert split_size(n, 0.0) == 0 and split_size(1, 0.2) == 1


def test_by_scale_split_holds_out_the_test_scale():
    rows = []
    for i, (shape, scale) in enumerate(
        [(sh, sc) for sh in "abcd" for sc in (0.15, 0.2, 0.25) for _ in range(5)]
    ):
        rows.append({"sample_id": f"c-{i:04d}", "corpus": "c", "stratum": shape, "scale": scale})
    m = pd.DataFrame(rows)
    s = make_splits(m, _settings(by_scale={"c": {"train": [0.15, 0.2], "test": [0.25]}})).merge(
        m, on="sample_id"
    )
    assert set(s.loc[s.split == "test", "scale"]) == {0.25}
    assert set(s.loc[s.split != "test", "scale"]) == {0.15, 0.2}
    assert (s.split == "val").sum() == round(
        0.1 * (s.scale < 0.25).sum()
    )  # val share of train scales


def test_by_scale_without_the_scale_rows_is_a_clear_error():
    m = _manifest(20).assign(scale=0.3)
    with pytest.raises(ValueError, match=r"corpus 'a' has no rows at train scales \[0.15\]"):
        make_splits(m, _settings(by_scale={"a": {"train": [0.15], "test": [0.25]}}))


def test_tiny_and_singleton_strata_still_split():
    m = _manifest(12)
    m.loc[0, "stratum"] = "unique"
    s = make_splits(m, _settings())
    assert set(s["split"]) == {"train", "val", "test"}


def test_guard_refuses_held_out_rows():
    s = make_splits(_manifest(), _settings())
    train = ids_in_split(s, "train")
    assert_trainable(train, s, rule="train_heads")  # fine
    leak = [*train[:5], ids_in_split(s, "test")[0]]
    with pytest.raises(
        LeakageError,
        match=r"rule train_heads: refusing to train on 1 held-out row\(s\); sample_id 'a-\d+' is in split 'test'",
    ):
        assert_trainable(leak, s, rule="train_heads")
    with pytest.raises(LeakageError, match="in split 'val'"):
        assert_trainable([ids_in_split(s, "val")[0]], s, rule="pretrain_backbone")
    assert_trainable(
        ids_in_split(s, ["train", "val"]), s, rule="train_heads", allowed=("train", "val")
    )
    with pytest.raises(LeakageError, match="can never be allowed"):
        assert_trainable(train, s, rule="x", allowed=("train", "test"))
    with pytest.raises(LeakageError, match="not in the split edge, e.g. sample_id 'zzz'"):
        assert_trainable(["zzz"], s, rule="x")


def test_fuse_manifest_unions_columns_and_refuses_duplicate_ids():
    a = pd.DataFrame(
        {
            "sample_id": ["a-1"],
            "corpus": "a",
            "sensor_id": "s",
            "caption": "x",
            "stratum": "p",
            "mass": 1.0,
            "rgb": [b"\x89PNG"],
        }
    )
    b = pd.DataFrame(
        {
            "sample_id": ["b-1"],
            "corpus": "b",
            "sensor_id": "t",
            "caption": "y",
            "stratum": "q",
            "source_split": "test",
        }
    )
    m = fuse_manifest([b, a])
    assert list(m["sample_id"]) == ["a-1", "b-1"] and "rgb" not in m.columns
    assert np.isnan(m.loc[1, "mass"]) and m.loc[1, "source_split"] == "test"
    with pytest.raises(
        ValueError,
        match=r"sample_id 'a-1' appears in more than one place \(corpora: \['a', 'b'\]\)",
    ):
        fuse_manifest([a, a.assign(corpus="b")])
    with pytest.raises(ValueError, match="corpus 'b': samples edge has no column 'stratum'"):
        fuse_manifest([a, b.drop(columns="stratum")])


def _objects_manifest(n_objects: int, contacts: int, seed: int = 5) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    mass = rng.lognormal(-3.0, 1.0, n_objects)
    obj = np.repeat(np.arange(n_objects), contacts)
    return pd.DataFrame(
        {
            "sample_id": [f"t-{i:05d}" for i in range(n_objects * contacts)],
            "corpus": "t",
            "stratum": "cube|hard|500",
            "scale": np.nan,
            "appearance_id": obj,
            "mass": mass[obj],
        }
    )


def test_split_by_object_keeps_every_object_in_one_split_and_every_class_in_test():
    from tacgen_lib.corpus.objects import mass_quantile_classes

    m = _objects_manifest(36, 6)
    shares = {"train": 0.5, "val": 0.1, "test": 0.4}
    s = make_splits(pd.concat([m, _manifest()]), _settings(by_object={"t": shares}))
    t = s[s["corpus"] == "t"].merge(m, on=["sample_id", "corpus"])
    per_object = t.groupby("appearance_id")["split"].agg(set)
    assert (per_object.map(len) == 1).all()
    counts = per_object.map(lambda x: next(iter(x))).value_counts().to_dict()
    assert counts == {"train": 18, "val": 4, "test": 14}
    masses = m.groupby("appearance_id")["mass"].first()
    classes = pd.Series(mass_quantile_classes(masses.to_numpy(), 3, where="t"), masses.index)
    test_objects = per_object.index[per_object.map(lambda x: "test" in x)]
    assert set(classes[test_objects]) == {0, 1, 2}
    # the other corpus's split is what it is without the by-object corpus
    alone = make_splits(_manifest(), _settings(seed=42))
    pd.testing.assert_frame_equal(s[s["corpus"] == "a"].reset_index(drop=True), alone)


def test_split_by_object_with_one_object_per_mass_class_is_refused():
    m = _objects_manifest(3, 4)
    shares = {"train": 0.5, "val": 0.1, "test": 0.4}
    with pytest.raises(
        ValueError, match=r"corpus 't' \(split by object\): mass class \d of 3 has 1"
    ):
        make_splits(m, _settings(by_object={"t": shares}))


def test_split_by_object_refuses_an_object_of_two_masses():
    m = _objects_manifest(12, 2)
    m.loc[1, "mass"] += 1.0
    with pytest.raises(ValueError, match=r"rows of object 0 \(appearance_id\) have different"):
        make_splits(m, _settings(by_object={"t": {"train": 0.5, "val": 0.1, "test": 0.4}}))
