"""Two runs of one config compared: how far their edges' numbers are apart, stage by stage, and
whether the findings' decisions agree. What a change of machine (a GPU against the CPU, another
CPU class, other kernels on one CPU) is checked by: `tools/device_check.py` prints it (its
``--compare`` mode for two finished runs), and the device test's end-to-end case
(tests/runtime/test_device.py) asserts it against `STAGE_TOLERANCES`.

An edge's stage is the first folder under results/ (features, align, generate, pixel, policy,
...). Its numbers are compared with the rows joined on its key: each vector column by the rows'
relative difference

    ||a_i - b_i||_2 / max(||a_i||_2, ||b_i||_2)      (0 where both rows are zero)

the distance of the two vectors over the longer one's length, and each float scalar column
(a summary's scores, Δs and interval bounds) by |a_i - b_i| / max|column| over both runs, its
difference on the column's own scale; neither depends on the scale of a feature or a metric.
A stage's difference is the largest over its edges' columns and rows. The decisions are
compared by id (`compare_decisions`): two machines may round a value differently and still
decide alike, which is what must hold.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tacgen_lib.io import edges

__all__ = [
    "DECISIONS",
    "WORKFLOW_TREE",
    "STAGE_TOLERANCES",
    "DecisionComparison",
    "EdgeDifference",
    "StageDifference",
    "compare_decisions",
    "copy_workflow",
    "stage_differences",
    "edge_differences",
    "relative_column_differences",
    "relative_row_differences",
]

#: a stage's largest relative vector difference (above) a GPU run may show against the CPU's
#: run of the same config (docs/cluster.md, "Checking a GPU against the CPU"). Inference alone
#: stays near float32 rounding; trained stages carry the rounding through their training steps,
#: and the pixel generators' dropout masks come from the GPU's own random generator.
STAGE_TOLERANCES: dict[str, float] = {
    "features": 0.01,
    "align": 0.05,
    "generate": 0.25,
    "policy": 0.05,
    "pixel": 1.0,
}
#: a stage not listed above
DEFAULT_TOLERANCE = 0.05
#: the findings' decisions edge, under a run's directory
DECISIONS = Path("results/report/findings/decisions.parquet")


@dataclass(frozen=True)
class EdgeDifference:
    """One vector column of one edge (`edge`, relative to the run's directory) in both runs:
    its `rows`, the largest relative difference `max_rel` and the key of that row
    (`worst_key`); `note` says why it could not be compared (`max_rel` is then inf)."""

    edge: str
    column: str
    rows: int
    max_rel: float
    worst_key: str = ""
    note: str = ""

    @property
    def stage(self) -> str:
        parts = Path(self.edge).parts
        return parts[1] if len(parts) > 1 and parts[0] == "results" else parts[0]


@dataclass(frozen=True)
class StageDifference:
    """A stage's vector edges in both runs: how many columns were compared, the largest
    relative difference and where (`worst`), its `tolerance` and whether it is within."""

    stage: str
    columns: int
    max_rel: float
    worst: EdgeDifference
    tolerance: float

    @property
    def within(self) -> bool:
        return self.max_rel <= self.tolerance


@dataclass(frozen=True)
class DecisionComparison:
    """The findings' decisions of both runs: how many each states, the ids whose decision
    differs or that only one run states, and for each of those a line with both runs'
    decisions, values and intervals (`lines`)."""

    decisions: int
    differ: tuple[str, ...]
    only_a: tuple[str, ...]
    only_b: tuple[str, ...]
    lines: tuple[str, ...] = ()

    @property
    def agree(self) -> bool:
        return not (self.differ or self.only_a or self.only_b)


#: Parquet column types (a sidecar's ``columns``) compared as float scalars.
_FLOAT_TYPES = frozenset({"double", "float", "halffloat"})


def _numeric_edges(run: Path) -> dict[str, list[str]]:
    """Edge path (relative to `run`) -> its vector and float scalar columns (vectors first),
    from the sidecars of the keyed edges under results/ (a hashed file without a key, such as
    weights, has none)."""
    out = {}
    for side in sorted((run / "results").rglob("*.sha256.json")):
        try:
            meta = json.loads(side.read_text())
        except json.JSONDecodeError:
            continue
        if not meta.get("key"):
            continue
        vectors = sorted(meta.get("vectors") or {})
        floats = sorted(
            c
            for c, t in (meta.get("columns") or {}).items()
            if t in _FLOAT_TYPES and c not in vectors
        )
        edge = side.with_name(side.name[: -len(".sha256.json")])
        if (vectors or floats) and edge.exists():  # a temporary edge leaves its sidecar
            out[edge.relative_to(run).as_posix()] = vectors + floats
    return out


def relative_row_differences(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per row, ||a_i - b_i|| / max(||a_i||, ||b_i||) in float64; 0 where both rows are zero."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    num = np.linalg.norm(a - b, axis=1)
    den = np.maximum(np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1))
    out = np.zeros_like(num)
    np.divide(num, den, out=out, where=den > 0)
    return out


def relative_column_differences(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per row, |a_i - b_i| / max(|a|, |b|) over both columns, in float64: a scalar column's
    difference on its own scale. NaN in both at a row is 0 there, NaN in one only inf; 0
    everywhere where both columns are all zero."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    finite = ~(nan_a | nan_b)
    scale = max(
        float(np.abs(a[finite]).max(initial=0.0)), float(np.abs(b[finite]).max(initial=0.0))
    )
    out = np.zeros(a.shape, dtype=np.float64)
    if scale > 0:
        out[finite] = np.abs(a[finite] - b[finite]) / scale
    out[nan_a ^ nan_b] = math.inf
    return out


def _read_columns(path: Path, columns: list[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(keys, column -> values) of a verified edge, read once: a vector column (N, d), a float
    scalar column (N,)."""
    edge = edges.read(path, columns=columns)
    out = {c: edge.vectors[c] for c in columns if c in edge.vectors}
    out.update({c: edge.frame[c].to_numpy(dtype=np.float64) for c in columns if c not in out})
    return edge.ids, out


def _difference(edge: str, column: str, ids_a, a: np.ndarray, ids_b, b: np.ndarray):
    if set(ids_a) != set(ids_b):
        only = sorted(set(ids_a) ^ set(ids_b))
        return EdgeDifference(
            edge, column, len(ids_a), math.inf, note=f"keys differ ({len(only)}, e.g. {only[0]!r})"
        )
    if a.ndim != b.ndim or (a.ndim == 2 and a.shape[1] != b.shape[1]):
        width = [x.shape[1] if x.ndim == 2 else "scalar" for x in (a, b)]
        return EdgeDifference(
            edge, column, len(ids_a), math.inf, note=f"dimension {width[0]} vs {width[1]}"
        )
    if not len(ids_a):
        return EdgeDifference(edge, column, 0, 0.0)
    where = {k: i for i, k in enumerate(ids_b)}
    b = b[[where[k] for k in ids_a]]
    rel = relative_row_differences(a, b) if a.ndim == 2 else relative_column_differences(a, b)
    worst = int(np.argmax(rel))
    return EdgeDifference(edge, column, len(ids_a), float(rel[worst]), str(ids_a[worst]))


def _edge_difference(run_a: Path, run_b: Path, edge: str, columns: list[str]) -> list:
    """The `EdgeDifference` of each of `columns` of one edge, each run's edge read once."""
    ids_a, a = _read_columns(run_a / edge, columns)
    try:
        ids_b, b = _read_columns(run_b / edge, columns)
    except (edges.EdgeError, FileNotFoundError, KeyError) as exc:
        return [
            EdgeDifference(edge, c, len(ids_a), math.inf, note=f"run b: {exc}") for c in columns
        ]
    return [_difference(edge, c, ids_a, a[c], ids_b, b[c]) for c in columns]


def edge_differences(run_a: str | Path, run_b: str | Path) -> list[EdgeDifference]:
    """Every vector and float scalar column of every keyed edge of run `run_a` (a workflow
    directory with results/) against the same edge of `run_b`, rows joined on the key; an edge
    `run_b` lacks (or with other keys or dimensions) has an infinite difference and a note.
    Edges only `run_b` has are listed too."""
    run_a, run_b = Path(run_a), Path(run_b)
    in_a, in_b = _numeric_edges(run_a), _numeric_edges(run_b)
    out = [
        d for edge, columns in in_a.items() for d in _edge_difference(run_a, run_b, edge, columns)
    ]
    out += [
        EdgeDifference(edge, column, 0, math.inf, note="only in run b")
        for edge, columns in in_b.items()
        if edge not in in_a
        for column in columns
    ]
    return out


def stage_differences(
    run_a: str | Path,
    run_b: str | Path,
    tolerances: dict[str, float] | None = None,
) -> list[StageDifference]:
    """Per stage (sorted), the largest relative difference of its edges' columns between the
    two runs (`edge_differences`), with its tolerance (`tolerances`, by default
    `STAGE_TOLERANCES`; `DEFAULT_TOLERANCE` for a stage not named)."""
    tolerances = STAGE_TOLERANCES if tolerances is None else tolerances
    by_stage: dict[str, list[EdgeDifference]] = {}
    for diff in edge_differences(run_a, run_b):
        by_stage.setdefault(diff.stage, []).append(diff)
    out = []
    for stage, diffs in sorted(by_stage.items()):
        worst = max(diffs, key=lambda d: d.max_rel)
        out.append(
            StageDifference(
                stage=stage,
                columns=len(diffs),
                max_rel=worst.max_rel,
                worst=worst,
                tolerance=tolerances.get(stage, DEFAULT_TOLERANCE),
            )
        )
    return out


def _decision_text(row: dict | None) -> str:
    if row is None:
        return "not stated"
    value = row["value"]
    text = f"{row['decision']}"
    if value == value:  # not NaN
        text += f" ({value:.4g}"
        if row["ci_low"] == row["ci_low"]:
            text += f" [{row['ci_low']:.4g}, {row['ci_high']:.4g}]"
        text += ")"
    return text


def compare_decisions(run_a: str | Path, run_b: str | Path) -> DecisionComparison | None:
    """The findings' decisions (`DECISIONS`: one row per decision the findings page states,
    keyed by `decision_id`, its verdict in `decision`, with its value, interval and threshold)
    of both runs compared; None where a run did not produce the edge."""
    paths = [Path(run_a) / DECISIONS, Path(run_b) / DECISIONS]
    if not all(p.exists() for p in paths):
        return None
    cols = ["decision_id", "decision", "value", "ci_low", "ci_high", "threshold"]
    a, b = (
        {r["decision_id"]: r for r in edges.read(p, columns=cols).frame.to_dict("records")}
        for p in paths
    )
    differ = tuple(sorted(k for k in a.keys() & b.keys() if a[k]["decision"] != b[k]["decision"]))
    only_a, only_b = tuple(sorted(a.keys() - b.keys())), tuple(sorted(b.keys() - a.keys()))
    lines = tuple(
        f"{k}: a {_decision_text(a.get(k))}; b {_decision_text(b.get(k))}"
        for k in (*differ, *only_a, *only_b)
    )
    return DecisionComparison(len(a), differ, only_a, only_b, lines)


#: what a run of the workflow reads from the repository: a copy of these is a workflow to run
WORKFLOW_TREE = ("Snakefile", "rules", "config", "workflow", "tacgen_lib", "profiles", "envs")


def copy_workflow(root: Path, dest: Path) -> Path:
    """A copy of the workflow at `root` (`WORKFLOW_TREE`, no ``__pycache__``) in `dest`, the
    folder made where missing; a run of it writes under `dest` only."""
    dest.mkdir(parents=True, exist_ok=True)
    for name in WORKFLOW_TREE:
        src = Path(root) / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(src, dest / name)
    return dest
