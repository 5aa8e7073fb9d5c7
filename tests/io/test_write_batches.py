"""edges.write_batches: an edge written one row group at a time is a verified edge like any
other; a bad key, a foreign schema or a failing producer leaves nothing behind."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tacgen_lib.io import edges
from tacgen_lib.io.hashed import EdgeError, sidecar_path

SCHEMA = pa.schema([("sample_id", pa.large_string()), ("png", pa.binary())])


def group(ids: list[str]) -> pa.Table:
    return pa.table({"sample_id": ids, "png": [i.encode() for i in ids]}, schema=SCHEMA)


def test_groups_become_row_groups_of_a_verified_edge(tmp_path: Path) -> None:
    path = tmp_path / "e.parquet"
    rows = edges.write_batches(path, SCHEMA, (group([f"s{i}", f"t{i}"]) for i in range(3)))
    assert rows == 6
    assert pq.ParquetFile(path).num_row_groups == 3
    edge = edges.read(path, require={"png": "bytes"})
    assert edge.frame["sample_id"].tolist() == ["s0", "t0", "s1", "t1", "s2", "t2"]
    again = tmp_path / "again.parquet"
    edges.write_batches(again, SCHEMA, (group([f"s{i}", f"t{i}"]) for i in range(3)))
    assert again.read_bytes() == path.read_bytes()


@pytest.mark.parametrize(
    ("groups", "match"),
    [
        ([["a", "b"], ["c", "a"]], "'a' appears more than once"),
        ([["a"], [""]], "null or empty sample_id at row 1"),
    ],
)
def test_a_bad_key_across_groups_is_refused_and_nothing_is_left(tmp_path, groups, match):
    path = tmp_path / "e.parquet"
    with pytest.raises(EdgeError, match=match):
        edges.write_batches(path, SCHEMA, (group(g) for g in groups))
    assert list(tmp_path.iterdir()) == []


def test_a_group_of_another_schema_is_refused(tmp_path: Path) -> None:
    other = pa.table({"sample_id": ["a"], "png": ["text"]})
    with pytest.raises(EdgeError, match="differ from the edge's schema"):
        edges.write_batches(tmp_path / "e.parquet", SCHEMA, [other])
    assert list(tmp_path.iterdir()) == []


def test_the_producers_error_passes_through_and_the_old_edge_stays(tmp_path: Path) -> None:
    path = tmp_path / "e.parquet"
    edges.write_batches(path, SCHEMA, [group(["old"])])
    before = path.read_bytes(), sidecar_path(path).read_bytes()

    def failing():
        yield group(["new"])
        raise FileNotFoundError("sample_id 'x': tactile image not found")

    with pytest.raises(FileNotFoundError, match="tactile image not found"):
        edges.write_batches(path, SCHEMA, failing())
    assert (path.read_bytes(), sidecar_path(path).read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["e.parquet", "e.parquet.sha256.json"]
