"""The Parquet edge contract (docs/layout.md, Edges): every arrow of the DAG is a verified Parquet file.

An edge is a table keyed by a unique, non-null string key (`sample_id`, or `episode_id` /
`sensor_id` for the few edges keyed by something else). Vectors are `fixed_size_list<float32>[d]`
columns; images are PNG bytes in `binary` columns.

Each edge is a hashed file (`tacgen_lib.io.hashed`: written atomically next to a sidecar
manifest `<file>.sha256.json`, here with its SHA-256, row count, key, column types and vector
dimensions). The loader recomputes the hash and checks the schema, the key and every vector,
and its errors name the file, the column and the offending key value.

Joins are always on the key (`join`), never on row order.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

if TYPE_CHECKING:  # pandas is imported where a frame is built: a vectors-only job never loads it
    import pandas as pd
from tacgen_lib.io.hashed import EdgeError, commit_file, verify, write_bytes


@dataclass
class Edge:
    """A verified edge: scalar columns in `frame`, vector columns as (N, d) float32 arrays.

    Row i of every vector belongs to `frame[key].iloc[i]`.
    """

    path: Path
    frame: pd.DataFrame
    vectors: dict[str, np.ndarray] = field(default_factory=dict)
    key: str = "sample_id"
    sha256: str = ""

    @property
    def ids(self) -> np.ndarray:
        """The key column as an array of str."""
        return self.frame[self.key].to_numpy(dtype=object)

    def __len__(self) -> int:
        return len(self.frame)

    def subset(self, ids: Iterable[str]) -> Edge:
        """Rows for `ids`, in the order given; an unknown id is an error naming it."""
        import pandas as pd

        ids = list(ids)
        pos = pd.Index(self.frame[self.key]).get_indexer(ids)
        if (pos < 0).any():
            missing = ids[int(np.flatnonzero(pos < 0)[0])]
            raise EdgeError(f"{self.path}: {self.key} {missing!r} is not in this edge")
        return Edge(
            path=self.path,
            frame=self.frame.iloc[pos].reset_index(drop=True),
            vectors={k: v[pos] for k, v in self.vectors.items()},
            key=self.key,
            sha256=self.sha256,
        )


def _is_null(value: object) -> bool:
    """None, a float NaN, or a pandas missing value (pandas is loaded if one can occur)."""
    if value is None:
        return True
    if isinstance(value, float):
        return value != value
    pd = sys.modules.get("pandas")
    missing = pd.isna(value) if pd is not None else False
    return isinstance(missing, (bool, np.bool_)) and bool(missing)


def _check_key(ids: Sequence, where: str, key: str) -> None:
    """The key holds non-empty, unique strings: else an error naming the row or the value
    (nulls are reported before other non-strings, then empty keys, then duplicates)."""
    bad = [row for row, v in enumerate(ids) if not isinstance(v, str)]
    if bad:
        nulls = [row for row in bad if _is_null(ids[row])]
        if nulls:
            raise EdgeError(f"{where}: column {key!r} has a null {key} at row {nulls[0]}")
        raise EdgeError(
            f"{where}: column {key!r} must hold strings; row {bad[0]} holds a {type(ids[bad[0]]).__name__}"
        )
    empty = [row for row, v in enumerate(ids) if not v]
    if empty:
        raise EdgeError(f"{where}: column {key!r} has an empty {key} at row {empty[0]}")
    seen: set[str] = set()
    for v in ids:
        if v in seen:
            raise EdgeError(f"{where}: {key} {v!r} appears more than once")
        seen.add(v)


def _check_vector(
    values: np.ndarray, name: str, ids: np.ndarray, where: str, key: str, dim: int | None
) -> None:
    if values.ndim != 2:
        raise EdgeError(f"{where}: column {name!r} must be (N, d), got shape {values.shape}")
    if dim is not None and values.shape[1] != dim:
        raise EdgeError(
            f"{where}: {key} {ids[0]!r} has {values.shape[1]} values in column {name!r}, expected {dim}"
        )
    finite = np.isfinite(values).all(axis=1)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        raise EdgeError(f"{where}: {key} {ids[row]!r} has a NaN or inf in column {name!r}")


def write(
    path: str | os.PathLike,
    frame: pd.DataFrame,
    vectors: Mapping[str, np.ndarray] | None = None,
    *,
    key: str = "sample_id",
    producer: str = "",
) -> str:
    """Write an edge atomically with its sidecar manifest; returns the SHA-256.

    frame: scalar columns (str, numbers, bool, bytes for PNG, lists of str), including `key`.
    vectors: column name -> (N, d) array, stored as fixed_size_list<float32>[d]; row i belongs
        to frame[key].iloc[i]. Non-finite values are refused (naming the key value).
    producer: the rule (or tool) that made the edge, recorded in the sidecar.
    """
    where = str(path)
    if key not in frame.columns:
        raise EdgeError(f"{where}: missing key column {key!r}")
    frame = frame.reset_index(drop=True)
    ids = frame[key].to_numpy(dtype=object)
    _check_key(ids, where, key)
    table = pa.Table.from_pandas(frame, preserve_index=False)
    return _write_table(path, table, ids, vectors or {}, key=key, producer=producer)


def write_vectors(
    path: str | os.PathLike,
    ids: Sequence[str],
    vectors: Mapping[str, np.ndarray],
    *,
    key: str = "sample_id",
    producer: str = "",
) -> str:
    """`write` of an edge that holds only its key and vector columns, without pandas.

    The key is stored as ``large_string``, the type pandas >= 3 gives a column of str, so
    the bytes equal `write`'s of ``pd.DataFrame({key: ids})`` there (a vectors-only job then
    need not import pandas, ~0.2 s of its start-up).
    """
    ids = np.asarray(list(ids), dtype=object)
    _check_key(ids, str(path), key)
    table = pa.table({key: pa.array(list(ids), type=pa.large_string())})
    return _write_table(path, table, ids, vectors, key=key, producer=producer)


def write_batches(
    path: str | os.PathLike,
    schema: pa.Schema,
    batches: Iterable[pa.Table],
    *,
    key: str = "sample_id",
    producer: str = "",
) -> int:
    """`write` of an edge too large to hold in memory: each table of `batches` (scalar
    columns of `schema`) becomes a row group as it comes, in a temporary file beside `path`
    that replaces it, its sidecar written first, once the last group is in. The key is checked
    across all groups (unique, non-empty strings). Returns the row count.

    The bytes differ from `write`'s of the same rows (one row group there); the same batches
    always give the same bytes.
    """
    path = Path(path)
    where = str(path)
    if key not in schema.names:
        raise EdgeError(f"{where}: missing key column {key!r}")
    schema = schema.remove_metadata()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    seen: set[str] = set()
    rows = 0

    def disk(call, *args, **kwargs):  # noqa: ANN001, ANN202 - a write, its OSError explained
        try:
            return call(*args, **kwargs)
        except OSError as exc:
            if exc.errno is None:
                raise
            raise OSError(
                exc.errno,
                f"{path}: cannot write the edge ({exc.strerror}); nothing was written there (the "
                "previous file, if any, is untouched); free space and rerun",
            ) from exc

    try:
        writer = disk(pq.ParquetWriter, tmp, schema, compression="zstd", write_statistics=False)
        try:
            for batch in batches:  # the producer's own errors pass through as they are
                if not batch.schema.remove_metadata().equals(schema):
                    raise EdgeError(
                        f"{where}: a row group's columns {batch.schema.names} / types differ "
                        f"from the edge's schema {schema}"
                    )
                ids = batch.column(key).to_pylist()
                for row, value in enumerate(ids, start=rows):
                    if not isinstance(value, str) or not value:
                        raise EdgeError(
                            f"{where}: column {key!r} has a null or empty {key} at row {row}"
                        )
                    if value in seen:
                        raise EdgeError(f"{where}: {key} {value!r} appears more than once")
                    seen.add(value)
                disk(writer.write_table, batch.replace_schema_metadata(None))
                rows += batch.num_rows
        finally:
            disk(writer.close)
        disk(
            commit_file,
            tmp,
            path,
            rows=rows,
            key=key,
            columns={f.name: str(f.type) for f in pq.read_schema(tmp)},
            vectors={},
            producer=producer,
        )
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    return rows


def _write_table(
    path: str | os.PathLike,
    table: pa.Table,
    ids: np.ndarray,
    vectors: Mapping[str, np.ndarray],
    *,
    key: str,
    producer: str,
) -> str:
    """Append the vector columns to `table` (scalar columns, key checked), write atomically."""
    path = Path(path)
    where = str(path)
    n = table.num_rows
    dims: dict[str, int] = {}
    for name, values in vectors.items():
        if name in table.column_names:
            raise EdgeError(
                f"{where}: column {name!r} given both as a scalar and as a vector column"
            )
        values = np.asarray(values)
        if values.shape[:1] != (n,):
            raise EdgeError(
                f"{where}: vector column {name!r} has {values.shape[0]} rows, the frame {n}"
            )
        _check_vector(values.astype(np.float64, copy=False), name, ids, where, key, None)
        d = int(values.shape[1])
        flat = pa.array(np.ascontiguousarray(values, dtype=np.float32).ravel(), type=pa.float32())
        table = table.append_column(name, pa.FixedSizeListArray.from_arrays(flat, d))
        dims[name] = d
    # Drop pandas' own metadata: it can differ between pandas versions, and edges must be
    # byte-identical for the same content.
    table = table.replace_schema_metadata(None)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd", write_statistics=False)
    data = sink.getvalue().to_pybytes()
    return write_bytes(
        path,
        data,
        rows=n,
        key=key,
        # column types as a reader will see them (Parquet renames list items, for one)
        columns={f.name: str(f.type) for f in pq.read_schema(pa.BufferReader(data))},
        vectors=dims,
        producer=producer,
    )


def _read_table(path: Path, columns: Iterable[str] | None) -> tuple[dict, pa.Table]:
    """The verified edge's sidecar and its table (only `columns` and the key), the column
    types checked against the sidecar."""
    where = str(path)
    meta = verify(path)
    key = meta["key"]
    absent = sorted(set(columns or ()) - set(meta["columns"]))
    if absent:
        have = ", ".join(sorted(meta["columns"]))
        raise EdgeError(f"{where}: missing column {absent[0]!r} (has: {have})")
    try:
        table = pq.read_table(path, columns=None if columns is None else sorted({key, *columns}))
    except (pa.ArrowInvalid, OSError) as exc:
        raise EdgeError(f"{where}: not a readable Parquet edge ({exc})") from exc
    for f in table.schema:
        if meta["columns"].get(f.name) != str(f.type):
            raise EdgeError(
                f"{where}: column {f.name!r} has type {f.type}, the manifest says {meta['columns'].get(f.name)}"
            )
    return meta, table


def _read_vector(table: pa.Table, name: str, ids: np.ndarray, where: str, meta: dict) -> np.ndarray:
    """Vector column `name` as an (N, d) float32 array; a null or non-finite row is an error
    naming its key value, a dimension other than the sidecar's one naming the first."""
    key = meta["key"]
    col = table.column(name).combine_chunks()
    d = col.type.list_size
    if col.null_count:
        row = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
        raise EdgeError(f"{where}: {key} {ids[row]!r} has a null in column {name!r}")
    values = col.flatten().to_numpy().reshape(-1, d)
    _check_vector(values, name, ids, where, key, meta["vectors"].get(name))
    return values


def read(
    path: str | os.PathLike,
    *,
    columns: Iterable[str] | None = None,
    require: Mapping[str, str | int] | None = None,
) -> Edge:
    """Load a verified edge.

    columns: read only these columns (the key is always read).
    require: column -> expectation; an int is a vector dimension, a string one of
        "str", "float", "int", "bytes", "list", "vector" (any dimension). A missing column or a
        wrong type or dimension is an error naming the file, the column and, where it is a row's
        fault, the key value.
    """
    path = Path(path)
    where = str(path)
    meta, table = _read_table(path, columns)
    key = meta["key"]
    vec_names = [f.name for f in table.schema if pa.types.is_fixed_size_list(f.type)]
    frame = table.drop_columns(vec_names).to_pandas(types_mapper=None)
    ids = frame[key].to_numpy(dtype=object)
    _check_key(ids, where, key)
    vectors = {name: _read_vector(table, name, ids, where, meta) for name in vec_names}
    for name, want in (require or {}).items():
        if name not in frame.columns and name not in vectors:
            have = ", ".join(sorted([*frame.columns, *vectors]))
            raise EdgeError(f"{where}: missing column {name!r} (has: {have})")
        if isinstance(want, int) and not isinstance(want, bool):
            if name not in vectors:
                raise EdgeError(
                    f"{where}: column {name!r} must be a vector of {want} float32 values"
                )
            if vectors[name].shape[1] != want:
                raise EdgeError(
                    f"{where}: {key} {ids[0]!r} has {vectors[name].shape[1]} values in column {name!r}, expected {want}"
                )
        elif want == "vector":
            if name not in vectors:
                raise EdgeError(
                    f"{where}: column {name!r} must be a fixed_size_list<float32> vector column"
                )
        else:
            _check_scalar_type(frame, name, str(want), where, key)
    return Edge(path=path, frame=frame, vectors=vectors, key=key, sha256=meta["sha256"])


def read_vectors(path: str | os.PathLike, column: str) -> tuple[np.ndarray, np.ndarray]:
    """(key values as an object array of str, vector column `column` (N, d) float32) of a
    verified edge, in file order, read without pandas: the checks of `read` with
    ``require={column: "vector"}``."""
    path = Path(path)
    where = str(path)
    meta, table = _read_table(path, [column])
    key = meta["key"]
    if column == key or not pa.types.is_fixed_size_list(table.schema.field(column).type):
        raise EdgeError(
            f"{where}: column {column!r} must be a fixed_size_list<float32> vector column"
        )
    ids = table.column(key).to_numpy(zero_copy_only=False).astype(object)
    _check_key(ids, where, key)
    return ids, _read_vector(table, column, ids, where, meta)


def read_vector_map(path: str | os.PathLike, column: str) -> dict[str, np.ndarray]:
    """Key -> row of vector column `column` of a verified edge (`read_vectors`: the same
    checks, no pandas): the lookup the stages that pick rows by sample_id read."""
    ids, vectors = read_vectors(path, column)
    return dict(zip(ids, vectors, strict=True))


_TYPE_CHECKS = {
    "str": lambda v: isinstance(v, str),
    "float": lambda v: (
        isinstance(v, (float, int, np.floating, np.integer)) and not isinstance(v, bool)
    ),
    "int": lambda v: isinstance(v, (int, np.integer)) and not isinstance(v, bool),
    "bytes": lambda v: isinstance(v, (bytes, bytearray)),
    "list": lambda v: isinstance(v, (list, np.ndarray)),
}


def _check_scalar_type(frame: pd.DataFrame, name: str, want: str, where: str, key: str) -> None:
    if want not in _TYPE_CHECKS:
        raise ValueError(
            f"edges.read: unknown type {want!r} (use one of {sorted(_TYPE_CHECKS)} or an int)"
        )
    check = _TYPE_CHECKS[want]
    col = frame[name]
    for sid, value in zip(frame[key], col, strict=True):
        if value is None or (isinstance(value, float) and np.isnan(value) and want != "float"):
            raise EdgeError(
                f"{where}: {key} {sid!r} has a null in column {name!r}, expected {want}"
            )
        if not check(value):
            raise EdgeError(
                f"{where}: {key} {sid!r} has a {type(value).__name__} in column {name!r}, expected {want}"
            )


def join(left: Edge, right: Edge, *, how: str = "inner") -> Edge:
    """Join two edges on their key (never on row order). Columns present in both are an error
    unless equal; the result is ordered by the left edge's key order."""
    if left.key != right.key:
        raise EdgeError(
            f"cannot join {left.path} (key {left.key!r}) with {right.path} (key {right.key!r})"
        )
    key = left.key
    clash = (set(left.frame.columns) | set(left.vectors)) & (
        set(right.frame.columns) | set(right.vectors)
    )
    clash.discard(key)
    if clash:
        raise EdgeError(
            f"joining {left.path} with {right.path}: both have column(s) {sorted(clash)}"
        )
    if how != "inner":
        raise ValueError("edges.join: only inner joins are supported")
    right_ids = set(right.ids)
    common = [i for i in left.ids if i in right_ids]
    a, b = left.subset(common), right.subset(common)
    frame = a.frame.merge(b.frame, on=key, how="inner", validate="one_to_one", sort=False)
    return Edge(path=left.path, frame=frame, vectors={**a.vectors, **b.vectors}, key=key, sha256="")
