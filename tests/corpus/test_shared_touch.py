"""Corpora of one rho grid share their tactile features only where their touch is
byte-identical, sample by sample (tacgen_lib.corpus.shared_touch)."""

from __future__ import annotations

import pandas as pd
import pytest

from tacgen_lib.corpus.shared_touch import touch_twins


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
