"""The Parquet edge contract: every bad input is refused with a message naming file, column, id."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tacgen_lib.io import edges, hashed
from tacgen_lib.io.edges import EdgeError
from tacgen_lib.io.images import decode_png, encode_png


def _frame(n: int = 5) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    return pd.DataFrame(
        {
            "sample_id": [f"p-{i:04d}" for i in range(n)],
            "mass": rng.random(n),
            "caption": [f"object {i}" for i in range(n)],
            "rgb": [encode_png(rng.integers(0, 256, (4, 6, 3), dtype=np.uint8)) for _ in range(n)],
            "adjectives": [["hard", "smooth"]] * n,
        }
    )


def _vec(n: int = 5, d: int = 8) -> np.ndarray:
    return np.random.default_rng(1).standard_normal((n, d)).astype(np.float32)


def test_round_trip_keeps_values_vectors_and_images(tmp_path):
    path = tmp_path / "e.parquet"
    frame, vec = _frame(), _vec()
    digest = edges.write(path, frame, {"v": vec}, producer="unit")
    edge = edges.read(path, require={"v": 8, "mass": "float", "rgb": "bytes", "caption": "str"})
    assert edge.sha256 == digest == hashed.sha256_file(path)
    assert list(edge.ids) == list(frame["sample_id"])
    np.testing.assert_array_equal(edge.vectors["v"], vec)
    assert edge.vectors["v"].dtype == np.float32
    np.testing.assert_array_equal(edge.frame["mass"], frame["mass"])
    assert (decode_png(edge.frame["rgb"][2]) == decode_png(frame["rgb"][2])).all()
    assert list(edge.frame["adjectives"][0]) == ["hard", "smooth"]
    meta = json.loads(hashed.sidecar_path(path).read_text())
    assert meta["vectors"] == {"v": 8} and meta["rows"] == 5 and meta["producer"] == "unit"
    assert "fixed_size_list<element: float>[8]" in meta["columns"]["v"]


def test_same_content_gives_identical_bytes(tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    assert edges.write(a, _frame(), {"v": _vec()}) == edges.write(b, _frame(), {"v": _vec()})
    assert a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (
            lambda f, v: f.assign(sample_id=["p-0000", "p-0001", "p-0001", "p-3", "p-4"]),
            "sample_id 'p-0001' appears more than once",
        ),
        (
            lambda f, v: f.assign(sample_id=["p-0000", None, "p-2", "p-3", "p-4"]),
            "null sample_id at row 1",
        ),
        (
            lambda f, v: f.assign(sample_id=["p-0000", "", "p-2", "p-3", "p-4"]),
            "empty sample_id at row 1",
        ),
        (lambda f, v: f.assign(sample_id=[0, 1, 2, 3, 4]), "must hold strings"),
        (lambda f, v: f.drop(columns="sample_id"), "missing key column 'sample_id'"),
    ],
)
def test_bad_keys_are_refused_at_write(tmp_path, mutate, message):
    frame = mutate(_frame(), _vec())
    with pytest.raises(EdgeError, match=message):
        edges.write(tmp_path / "e.parquet", frame, {"v": _vec()})
    assert not (tmp_path / "e.parquet").exists()


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_vector_is_refused_naming_the_sample(tmp_path, bad):
    vec = _vec()
    vec[3, 2] = bad
    with pytest.raises(
        EdgeError, match=r"e\.parquet: sample_id 'p-0003' has a NaN or inf in column 'v'"
    ):
        edges.write(tmp_path / "e.parquet", _frame(), {"v": vec})
    assert not (tmp_path / "e.parquet").exists()


def test_wrong_dimension_is_refused_at_read(tmp_path):
    path = tmp_path / "e.parquet"
    edges.write(path, _frame(), {"tactile": _vec(d=767)})
    with pytest.raises(
        EdgeError, match=r"sample_id 'p-0000' has 767 values in column 'tactile', expected 768"
    ):
        edges.read(path, require={"tactile": 768})


def test_missing_column_is_named(tmp_path):
    path = tmp_path / "e.parquet"
    edges.write(path, _frame(), {"v": _vec()})
    with pytest.raises(EdgeError, match=r"e\.parquet: missing column 'force_p50'"):
        edges.read(path, require={"force_p50": "float"})


def test_wrong_scalar_type_is_named(tmp_path):
    path = tmp_path / "e.parquet"
    edges.write(path, _frame(), {"v": _vec()})
    with pytest.raises(
        EdgeError, match=r"sample_id 'p-0000' has a str in column 'caption', expected float"
    ):
        edges.read(path, require={"caption": "float"})


def test_tampered_edge_is_refused_and_left_untouched(tmp_path):
    path = tmp_path / "e.parquet"
    edges.write(path, _frame(), {"v": _vec()})
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01  # one flipped bit
    path.write_bytes(bytes(data))
    with pytest.raises(EdgeError, match=r"e\.parquet: SHA-256 .* does not match the manifest"):
        edges.read(path)
    assert path.read_bytes() == bytes(data)  # the loader never rewrites or deletes


def test_missing_sidecar_and_missing_file(tmp_path):
    path = tmp_path / "e.parquet"
    with pytest.raises(EdgeError, match="does not exist"):
        edges.read(path)
    edges.write(path, _frame())
    hashed.sidecar_path(path).unlink()
    with pytest.raises(EdgeError, match="no manifest"):
        edges.read(path)


def test_failed_write_leaves_no_half_written_file(tmp_path, monkeypatch):
    path = tmp_path / "e.parquet"
    edges.write(path, _frame(3))
    before = path.read_bytes()

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(edges.os, "fsync", boom)
    with pytest.raises(OSError, match="disk full"):
        edges.write(path, _frame(5))
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


def test_join_is_on_key_not_row_order(tmp_path):
    left = tmp_path / "l.parquet"
    right = tmp_path / "r.parquet"
    f = _frame()
    edges.write(left, f[["sample_id", "mass"]], {"v": _vec()})
    shuffled = f[["sample_id", "caption"]].iloc[[4, 2, 0, 3]]
    edges.write(right, shuffled, {"t": _vec(4, 3)[[0, 1, 2, 3]]})
    joined = edges.join(edges.read(left), edges.read(right))
    assert list(joined.ids) == ["p-0000", "p-0002", "p-0003", "p-0004"]
    row = list(joined.ids).index("p-0002")
    assert joined.frame["caption"][row] == "object 2"
    np.testing.assert_array_equal(joined.vectors["t"][row], _vec(4, 3)[1])
    np.testing.assert_array_equal(joined.vectors["v"][row], _vec()[2])


def test_join_refuses_clashing_columns(tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    edges.write(a, _frame()[["sample_id", "mass"]])
    edges.write(b, _frame()[["sample_id", "mass"]])
    with pytest.raises(EdgeError, match=r"both have column\(s\) \['mass'\]"):
        edges.join(edges.read(a), edges.read(b))


def test_subset_names_unknown_id(tmp_path):
    path = tmp_path / "e.parquet"
    edges.write(path, _frame())
    with pytest.raises(EdgeError, match="sample_id 'p-9999' is not in this edge"):
        edges.read(path).subset(["p-0001", "p-9999"])


def test_empty_edge_round_trips(tmp_path):
    path = tmp_path / "e.parquet"
    edges.write(
        path,
        pd.DataFrame({"epoch_id": pd.Series([], dtype=object), "loss": pd.Series([], dtype=float)}),
        key="epoch_id",
    )
    assert len(edges.read(path)) == 0


def test_vectors_only_edge_is_the_same_file_without_pandas(tmp_path):
    """write_vectors / read_vectors (the sampling jobs' path) give the bytes `write` gives for
    a key-and-vectors frame, and read back what `read` reads, in file order."""
    ids = [f"p-{i:04d}" for i in (3, 0, 4, 1, 2)]
    vec = _vec()
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    digest = edges.write_vectors(a, ids, {"v": vec}, producer="unit")
    assert digest == edges.write(b, pd.DataFrame({"sample_id": ids}), {"v": vec}, producer="unit")
    assert a.read_bytes() == b.read_bytes()
    side_a, side_b = (json.loads(hashed.sidecar_path(p).read_text()) for p in (a, b))
    assert {**side_a, "file": ""} == {**side_b, "file": ""}
    got_ids, got = edges.read_vectors(a, "v")
    assert list(got_ids) == ids and got.dtype == np.float32
    np.testing.assert_array_equal(got, edges.read(a).vectors["v"])
    # the key -> vector lookup: the same rows, by key
    lookup = edges.read_vector_map(a, "v")
    assert list(lookup) == ids
    for i, key in enumerate(ids):
        np.testing.assert_array_equal(lookup[key], got[i])


def test_vectors_only_path_refuses_what_the_frame_path_refuses(tmp_path):
    path = tmp_path / "e.parquet"
    with pytest.raises(EdgeError, match="sample_id 'p-1' appears more than once"):
        edges.write_vectors(path, ["p-0", "p-1", "p-1"], {"v": _vec(3)})
    with pytest.raises(EdgeError, match="null sample_id at row 1"):
        edges.write_vectors(path, ["p-0", None, "p-2"], {"v": _vec(3)})
    vec = _vec(3)
    vec[2, 0] = np.nan
    with pytest.raises(EdgeError, match="sample_id 'p-2' has a NaN or inf in column 'v'"):
        edges.write_vectors(path, ["p-0", "p-1", "p-2"], {"v": vec})
    assert not path.exists()
    edges.write(path, _frame(), {"v": _vec()})
    with pytest.raises(EdgeError, match=r"e\.parquet: missing column 'w' \(has: "):
        edges.read_vectors(path, "w")
    with pytest.raises(EdgeError, match="column 'mass' must be a fixed_size_list"):
        edges.read_vectors(path, "mass")
    path.write_bytes(path.read_bytes()[:-1] + b"\0")
    with pytest.raises(EdgeError, match="does not match the manifest"):
        edges.read_vectors(path, "v")
