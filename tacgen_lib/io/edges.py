"""The Parquet edge contract (DESIGN §3): every arrow of the DAG is a verified Parquet file.

An edge is a table keyed by a unique, non-null string key (`sample_id`, or `episode_id` /
`sensor_id` for the few edges keyed by something else). Vectors are `fixed_size_list<float32>[d]`
columns; images are PNG bytes in `binary` columns.

Each edge is written atomically (temporary file in the same folder, fsync, rename) next to a
sidecar manifest `<file>.sha256.json` holding its SHA-256, row count, key, column types and
vector dimensions. The sidecar is written first, so a crash leaves either the old pair, or a
sidecar without its edge (Snakemake then reruns the job), never an edge that verifies against
the wrong hash. The loader recomputes the hash and checks the schema, the key and every vector,
and its errors name the file, the column and the offending key value.

Joins are always on the key (`join`), never on row order.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

__all__ = [
    "Edge",
    "EdgeError",
    "write",
    "read",
    "verify",
    "join",
    "sha256_file",
    "sidecar_path",
    "record_file",
    "write_bytes",
    "atomic_write_bytes",
]

SIDECAR_SUFFIX = ".sha256.json"
_HASH_CHUNK = 1 << 20


class EdgeError(ValueError):
    """An edge breaks the contract: the message names the file, the column and the key value."""


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


def sidecar_path(path: str | os.PathLike) -> Path:
    """Where the manifest entry of an edge lives: `<edge>.sha256.json`."""
    return Path(str(path) + SIDECAR_SUFFIX)


def sha256_file(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(_HASH_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` through a temporary file in the same folder and a rename."""
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno is not None:
            # a full disk or a read-only folder: say which file, and that nothing was replaced
            raise OSError(
                exc.errno,
                f"{path}: cannot write {len(data)} bytes ({exc.strerror}); nothing was written "
                "there (the previous file, if any, is untouched); free space and rerun",
            ) from exc
        raise


def _check_key(ids: pd.Series, where: str, key: str) -> None:
    if len(ids) == 0:
        return
    if ids.isna().any():
        row = int(np.flatnonzero(ids.isna().to_numpy())[0])
        raise EdgeError(f"{where}: column {key!r} has a null {key} at row {row}")
    non_str = ~ids.map(lambda v: isinstance(v, str)).to_numpy(dtype=bool)
    if non_str.any():
        row = int(np.flatnonzero(non_str)[0])
        raise EdgeError(
            f"{where}: column {key!r} must hold strings; row {row} holds a {type(ids.iloc[row]).__name__}"
        )
    empty = ids.str.len() == 0
    if empty.any():
        raise EdgeError(
            f"{where}: column {key!r} has an empty {key} at row {int(np.flatnonzero(empty.to_numpy())[0])}"
        )
    dup = ids.duplicated()
    if dup.any():
        raise EdgeError(f"{where}: {key} {ids[dup].iloc[0]!r} appears more than once")


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
    path = Path(path)
    where = str(path)
    vectors = dict(vectors or {})
    if key not in frame.columns:
        raise EdgeError(f"{where}: missing key column {key!r}")
    frame = frame.reset_index(drop=True)
    _check_key(frame[key], where, key)
    ids = frame[key].to_numpy(dtype=object)
    table = pa.Table.from_pandas(frame, preserve_index=False)
    dims: dict[str, int] = {}
    for name, values in vectors.items():
        if name in frame.columns:
            raise EdgeError(
                f"{where}: column {name!r} given both as a scalar and as a vector column"
            )
        values = np.asarray(values)
        if values.shape[:1] != (len(frame),):
            raise EdgeError(
                f"{where}: vector column {name!r} has {values.shape[0]} rows, the frame {len(frame)}"
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
        rows=len(frame),
        key=key,
        # column types as a reader will see them (Parquet renames list items, for one)
        columns={f.name: str(f.type) for f in pq.read_schema(pa.BufferReader(data))},
        vectors=dims,
        producer=producer,
    )


def _write_sidecar(path: Path, digest: str, fields: Mapping) -> None:
    sidecar = {"file": path.name, "sha256": digest, **fields}
    atomic_write_bytes(
        sidecar_path(path), (json.dumps(sidecar, indent=1, sort_keys=True) + "\n").encode()
    )


def write_bytes(path: str | os.PathLike, data: bytes, **fields) -> str:
    """Write any file atomically with its sidecar manifest (written first); returns the SHA-256.

    fields: what the sidecar records besides file and sha256 (rows, key, columns, vectors,
    producer, ...), so `verify` checks the file and the report lists it like an edge.
    """
    path = Path(path)
    digest = hashlib.sha256(data).hexdigest()
    _write_sidecar(path, digest, fields)
    atomic_write_bytes(path, data)
    return digest


def record_file(path: str | os.PathLike, *, producer: str = "", kind: str = "weights") -> str:
    """Hash a non-Parquet output (model weights, a table file) into its sidecar manifest, so it
    is verified by `verify` and listed in the report like an edge. Returns the SHA-256."""
    path = Path(path)
    digest = sha256_file(path)
    fields = {
        "rows": None,
        "key": None,
        "columns": {},
        "vectors": {},
        "producer": producer,
        "kind": kind,
    }
    _write_sidecar(path, digest, fields)
    return digest


def verify(path: str | os.PathLike) -> dict:
    """Check an edge's bytes against its sidecar; returns the sidecar. Reads no rows."""
    path = Path(path)
    if not path.exists():
        raise EdgeError(f"{path}: edge file does not exist")
    side = sidecar_path(path)
    if not side.exists():
        raise EdgeError(
            f"{path}: no manifest {side.name} beside it; rebuild the edge with its rule"
        )
    try:
        meta = json.loads(side.read_text())
    except json.JSONDecodeError as exc:
        raise EdgeError(f"{side}: manifest is not valid JSON ({exc})") from exc
    got = sha256_file(path)
    if got != meta.get("sha256"):
        raise EdgeError(
            f"{path}: SHA-256 {got[:16]}… does not match the manifest's {str(meta.get('sha256'))[:16]}…; "
            "the edge was changed after it was written: delete it and rerun its rule"
        )
    return meta


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
    meta = verify(path)
    key = meta["key"]
    try:
        table = pq.read_table(path, columns=None if columns is None else sorted({key, *columns}))
    except (pa.ArrowInvalid, OSError) as exc:
        raise EdgeError(f"{where}: not a readable Parquet edge ({exc})") from exc
    schema_now = {f.name: str(f.type) for f in table.schema}
    for name, typ in schema_now.items():
        if meta["columns"].get(name) != typ:
            raise EdgeError(
                f"{where}: column {name!r} has type {typ}, the manifest says {meta['columns'].get(name)}"
            )
    vec_names = [f.name for f in table.schema if pa.types.is_fixed_size_list(f.type)]
    scalar = table.drop_columns(vec_names)
    frame = scalar.to_pandas(types_mapper=None)
    _check_key(frame[key], where, key)
    ids = frame[key].to_numpy(dtype=object)
    vectors: dict[str, np.ndarray] = {}
    for name in vec_names:
        col = table.column(name).combine_chunks()
        d = col.type.list_size
        if col.null_count:
            row = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
            raise EdgeError(f"{where}: {key} {ids[row]!r} has a null in column {name!r}")
        values = col.flatten().to_numpy().reshape(-1, d)
        _check_vector(values, name, ids, where, key, meta["vectors"].get(name))
        vectors[name] = values
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
