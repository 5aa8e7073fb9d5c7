"""Comparing the edges of two runs of one config: which hashed files are identical, and how far
apart the numbers of those that are not lie.

Two runs on one machine with the same config and seeds write the same bytes. On another CPU
class, under other kernels or on a GPU they do not: floats round differently, and a training
loop carries a last-bit difference into its weights. What must hold there is the conclusions
(`tacgen_lib.report.decisions`), and the edges are compared within a tolerance instead
(`compare_runs`, `tools/compare_runs.py`).

Every hashed file under each run's ``results/`` is found by its sidecar (`hashed.sidecar_path`).
Files with equal SHA-256 are identical. A Parquet edge that is not is read (verified) from both
runs and joined on its key: its key sets, its non-float columns (equal or not) and, per float
column and vector column, the largest difference relative to the column's scale,
``max |a - b| / max |a|`` over both runs' values (`relative_difference`), which stays finite
for a column that holds zeros. A file that is not an edge (weights, a figure's table) is
compared by hash only. The tolerance of each difference is its stage's (the first folder under
``results/``: corpus, features, align, ...), given by the caller.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from tacgen_lib.io import edges
from tacgen_lib.io.hashed import SIDECAR_SUFFIX, sidecar_path

__all__ = [
    "EDGE_COMPARISON_COLUMNS",
    "STAGE_TOLERANCES",
    "compare_edge",
    "compare_runs",
    "relative_difference",
    "stage_of",
]

#: One row per compared file and, for an edge that differs, per column that differs.
EDGE_COMPARISON_COLUMNS = [
    "edge",  # the path under results/
    "stage",  # its first folder (stage_of)
    "status",  # identical | within | beyond | keys differ | values differ | only in a | only in b | hash differs
    "column",  # the column compared ("" for a whole-file status)
    "rows",  # rows compared (joined on the key)
    "max_abs",  # the largest |a - b| of the column
    "max_rel",  # relative_difference of the column
    "tolerance",  # the stage's tolerance on max_rel
]

#: The largest relative difference (`relative_difference`) accepted between two runs of one
#: config on other CPU kernels, per stage that no training loop touches: the simulated corpus
#: and the tactile preprocessing are computed, not learnt, and differ by rounding alone. Every
#: stage downstream of a training loop (features: the backbones' pretraining; align, probes,
#: generate, policy, ...) is reported, not bounded: a last-bit difference in a gradient step
#: is carried into the weights, and what must agree there is the decisions.
STAGE_TOLERANCES: dict[str, float] = {"corpus": 1e-6, "preprocess": 1e-6}


def stage_of(edge: str) -> str:
    """The stage of an edge path relative to ``results/``: its first folder (``corpus``,
    ``features``, ``align``, ...), or ``""`` for a file at the top."""
    parts = Path(edge).parts
    return parts[0] if len(parts) > 1 else ""


def relative_difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(max |a - b|, max |a - b| / max(|a|, |b|)) over two equal-shape float arrays; NaN at the
    same place in both counts as equal, NaN in one only as an infinite difference. Both 0 for
    empty or all-zero arrays."""
    a64, b64 = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a64.shape != b64.shape:
        raise ValueError(f"relative_difference: shapes {a64.shape} and {b64.shape} differ")
    both_nan = np.isnan(a64) & np.isnan(b64)
    one_nan = np.isnan(a64) ^ np.isnan(b64)
    if one_nan.any():
        return math.inf, math.inf
    keep = ~both_nan
    if not keep.any():
        return 0.0, 0.0
    diff = np.abs(a64[keep] - b64[keep])
    scale = max(float(np.abs(a64[keep]).max()), float(np.abs(b64[keep]).max()))
    max_abs = float(diff.max())
    return max_abs, (max_abs / scale if scale > 0 else 0.0)


def _row(edge: str, status: str, column: str = "", **numbers: float) -> dict:
    return {
        "edge": edge,
        "stage": stage_of(edge),
        "status": status,
        "column": column,
        "rows": numbers.get("rows", math.nan),
        "max_abs": numbers.get("max_abs", math.nan),
        "max_rel": numbers.get("max_rel", math.nan),
        "tolerance": numbers.get("tolerance", math.nan),
    }


def _is_float(series: pd.Series) -> bool:
    return pd.api.types.is_float_dtype(series.dtype)


def compare_edge(a: Path, b: Path, edge: str, tolerance: float) -> list[dict]:
    """The rows of `EDGE_COMPARISON_COLUMNS` of one Parquet edge present in both runs (`a`, `b`
    its two paths, `edge` its name under ``results/``): one ``identical`` row if the bytes are
    equal; else ``keys differ`` if the key sets differ, else one row per column that differs,
    ``within`` or ``beyond`` `tolerance` for a float or vector column, ``values differ`` for any
    other."""
    ea, eb = edges.read(a), edges.read(b)
    if ea.sha256 == eb.sha256:
        return [_row(edge, "identical", rows=len(ea))]
    ids_a, ids_b = set(ea.ids), set(eb.ids)
    if ids_a != ids_b:
        return [_row(edge, "keys differ", rows=len(ids_a & ids_b))]
    eb = eb.subset(ea.ids)
    rows = []
    n = len(ea)
    fa, fb = ea.frame.reset_index(drop=True), eb.frame.reset_index(drop=True)
    for col in fa.columns:
        if col not in fb.columns:
            rows.append(_row(edge, "values differ", col, rows=n))
        elif _is_float(fa[col]) and _is_float(fb[col]):
            d_abs, d_rel = relative_difference(fa[col].to_numpy(), fb[col].to_numpy())
            if d_abs > 0:
                status = "within" if d_rel <= tolerance else "beyond"
                rows.append(
                    _row(
                        edge, status, col, rows=n, max_abs=d_abs, max_rel=d_rel, tolerance=tolerance
                    )
                )
        elif not fa[col].equals(fb[col]):  # strings, integers, bytes: a data move, not a float
            rows.append(_row(edge, "values differ", col, rows=n))
    for col, va in ea.vectors.items():
        vb = eb.vectors.get(col)
        if vb is None or vb.shape != va.shape:
            rows.append(_row(edge, "values differ", col, rows=n))
            continue
        d_abs, d_rel = relative_difference(va, vb)
        if d_abs > 0:
            status = "within" if d_rel <= tolerance else "beyond"
            rows.append(
                _row(edge, status, col, rows=n, max_abs=d_abs, max_rel=d_rel, tolerance=tolerance)
            )
    # equal numbers in other bytes (a column's order, metadata): report it, not silently pass
    return rows or [_row(edge, "within", rows=n, max_abs=0.0, max_rel=0.0, tolerance=tolerance)]


def _hashed_files(results: Path) -> dict[str, Path]:
    """name under `results` -> path of every file with a sidecar."""
    out = {}
    for side in sorted(results.rglob(f"*{SIDECAR_SUFFIX}")):
        path = side.with_name(side.name[: -len(SIDECAR_SUFFIX)])
        if path.exists():
            out[str(path.relative_to(results))] = path
    return out


def compare_runs(
    results_a: str | Path,
    results_b: str | Path,
    tolerances: Mapping[str, float],
    *,
    default_tolerance: float = 0.0,
) -> pd.DataFrame:
    """Every hashed file of two runs' ``results/`` folders compared (`EDGE_COMPARISON_COLUMNS`,
    ordered by edge): Parquet edges by `compare_edge` with the tolerance of their stage
    (`tolerances`: stage -> the largest max_rel accepted; `default_tolerance` for a stage not
    named), other files by hash (``identical`` or ``hash differs``), and files of one run only
    (``only in a`` / ``only in b``)."""
    a, b = _hashed_files(Path(results_a)), _hashed_files(Path(results_b))
    rows = []
    for name in sorted(set(a) | set(b)):
        if name not in b:
            rows.append(_row(name, "only in a"))
            continue
        if name not in a:
            rows.append(_row(name, "only in b"))
            continue
        tol = float(tolerances.get(stage_of(name), default_tolerance))
        if name.endswith(".parquet") and _is_edge(a[name]):
            rows += compare_edge(a[name], b[name], name, tol)
        else:
            same = _sha(a[name]) == _sha(b[name])
            rows.append(_row(name, "identical" if same else "hash differs"))
    return pd.DataFrame(rows, columns=EDGE_COMPARISON_COLUMNS)


def _sidecar(path: Path) -> dict:
    return json.loads(sidecar_path(path).read_text())


def _sha(path: Path) -> str:
    return str(_sidecar(path).get("sha256"))


def _is_edge(path: Path) -> bool:
    """A keyed Parquet edge (its sidecar names a key), not a hashed table file."""
    return bool(_sidecar(path).get("key"))
