"""Hashed files: every output of the DAG (a Parquet edge, model weights, a table) is written
atomically (temporary file in the same folder, fsync, rename) next to a sidecar manifest
`<file>.sha256.json` holding its SHA-256 and what else its writer records (rows, key, column
types, vector dimensions, producing rule). The sidecar is written first, so a crash leaves
either the old pair or a sidecar without its file (Snakemake then reruns the job), never a file
that verifies against the wrong hash. `verify` recomputes the hash.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pandas is imported where a frame is built: a vectors-only job never loads it
    pass


SIDECAR_SUFFIX = ".sha256.json"


_HASH_CHUNK = 1 << 20


class EdgeError(ValueError):
    """An edge breaks the contract: the message names the file, the column and the key value."""


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


def commit_file(tmp: str | os.PathLike, path: str | os.PathLike, **fields) -> str:
    """Install `tmp`, a finished file written beside `path` (same folder), as `path`: its
    SHA-256 into the sidecar first, then the rename. For a file too large to hold in memory
    (`write_bytes` takes the bytes); `fields` as there. Returns the SHA-256."""
    tmp, path = Path(tmp), Path(path)
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    digest = sha256_file(tmp)
    _write_sidecar(path, digest, fields)
    os.replace(tmp, path)
    return digest


def record_file(path: str | os.PathLike, *, producer: str = "", kind: str) -> str:
    """Hash a non-Parquet output (model weights, a table file: `kind`) into its sidecar
    manifest, so it is verified by `verify` and listed in the report like an edge. Returns the
    SHA-256."""
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
