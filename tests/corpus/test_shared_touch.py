"""Corpora of one rho grid share their tactile features only where their touch is
byte-identical, sample by sample (tacgen_lib.corpus.shared_touch)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tacgen_lib.corpus.shared_touch import frame_twins, shared_vectors, touch_twins


def corpus(name: str, frames: list[bytes]) -> pd.DataFrame:
    return pd.DataFrame(
        {"sample_id": [f"{name}-{i:06d}" for i in range(len(frames))], "tactile": frames}
    )


def test_twins_pair_the_same_sample_index_of_each_corpus():
    frames = [b"\x89PNG a", b"\x89PNG b", b"\x89PNG c"]
    got = touch_twins(corpus("sim_natural_r0", frames), corpus("sim_natural_r1", frames)[::-1])
    assert got == {f"sim_natural_r0-{i:06d}": f"sim_natural_r1-{i:06d}" for i in range(3)}


def test_a_differing_frame_is_refused_naming_the_sample():
    source = corpus("a", [b"x", b"y"])
    with pytest.raises(ValueError, match=r"rule r: sample_id 'b-000001' has tactile bytes"):
        touch_twins(source, corpus("b", [b"x", b"z"]), where="rule r")
    with pytest.raises(ValueError, match="'b-000000' has tactile bytes"):
        touch_twins(source, corpus("b", [None, b"y"]))


def test_a_sample_without_twin_is_refused():
    with pytest.raises(ValueError, match=r"sample index 000002 .* \(3 against 2 samples\)"):
        touch_twins(corpus("a", [b"x", b"y", b"z"]), corpus("b", [b"x", b"y"]))


def rgb_corpus(name: str, frames: list[bytes]) -> pd.DataFrame:
    return corpus(name, frames).rename(columns={"tactile": "rgb"})


def test_frame_twins_take_each_frame_from_the_first_end_that_has_it():
    r0 = rgb_corpus("sim_natural_r0", [b"u0", b"u1", b"same"])
    r1 = rgb_corpus("sim_natural_r1", [b"m0", b"m1", b"same"])
    mid = rgb_corpus("sim_natural_r05", [b"m0", b"u1", b"same"])[::-1]
    got = frame_twins(mid, [r0, r1])
    assert got == {
        "sim_natural_r05-000000": (1, "sim_natural_r1-000000"),
        "sim_natural_r05-000001": (0, "sim_natural_r0-000001"),
        "sim_natural_r05-000002": (0, "sim_natural_r0-000002"),
    }


def test_a_frame_of_neither_end_or_a_missing_sample_is_refused():
    r0, r1 = rgb_corpus("a", [b"x", b"y"]), rgb_corpus("b", [b"p", b"q"])
    with pytest.raises(
        ValueError,
        match=r"rule r: sample_id 'c-000001' has rgb bytes other than 'a-000001', 'b-000001'",
    ):
        frame_twins(rgb_corpus("c", [b"x", b"z"]), [r0, r1], where="rule r")
    with pytest.raises(ValueError, match=r"'c-000000' has rgb bytes"):
        frame_twins(rgb_corpus("c", [None, b"y"]), [r0, r1])
    with pytest.raises(ValueError, match=r"sample index 000002 .* \(2 against 3 samples\)"):
        frame_twins(rgb_corpus("c", [b"x", b"y", b"z"]), [r0, r1])


def test_shared_vectors_copy_each_twins_row_from_its_source():
    rng = np.random.default_rng(0)
    a = {"vit": rng.normal(size=(3, 4)).astype(np.float32), "pixel": rng.normal(size=(3, 2))}
    b = {"vit": rng.normal(size=(3, 4)).astype(np.float32), "pixel": rng.normal(size=(3, 2))}
    sources = [(["a-0", "a-1", "a-2"], a), (["b-2", "b-0", "b-1"], b)]
    twins = {"c-0": (1, "b-0"), "c-1": (0, "a-1"), "c-2": (1, "b-2")}
    got = shared_vectors(["c-2", "c-0", "c-1"], twins, sources)
    for name in ("vit", "pixel"):
        assert got[name].dtype == a[name].dtype
        assert np.array_equal(got[name], np.stack([b[name][0], b[name][1], a[name][1]]))
    with pytest.raises(ValueError, match="feature columns differ"):
        shared_vectors(["c-0"], twins, [sources[0], (sources[1][0], {"vit": b["vit"]})])
