"""Two runs of one config compared: how far their vector edges are apart, stage by stage, and
whether the findings' decisions agree. What a change of machine (a GPU against the CPU, another
CPU class) is checked by: `tools/device_check.py` prints it, and the device test's end-to-end
case (tests/runtime/test_device.py) asserts it against `STAGE_TOLERANCES`.

A vector edge is a hashed Parquet edge whose sidecar lists vector columns (`tacgen_lib.io.edges`);
its stage is the first folder under results/ (features, align, generate, pixel, policy, ...).
For each vector column the rows are joined on the edge's key, and a row's relative difference is

    ||a_i - b_i||_2 / max(||a_i||_2, ||b_i||_2)      (0 where both rows are zero)

the distance of the two vectors over the longer one's length, so a stage's tolerance does not
depend on the scale of its features. A stage's difference is the largest over its edges' rows.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tacgen_lib.io import edges

__all__ = [
    "DECISIONS",
    "STAGE_TOLERANCES",
    "DecisionComparison",
    "EdgeDifference",
    "StageDifference",
    "compare_decisions",
    "stage_differences",
    "vector_edge_differences",
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
    """The findings' decisions of both runs: how many each states, and the ids whose decision
    differs or that only one run states."""

    decisions: int
    differ: tuple[str, ...]
    only_a: tuple[str, ...]
    only_b: tuple[str, ...]

    @property
    def agree(self) -> bool:
        return not (self.differ or self.only_a or self.only_b)


def _vector_edges(run: Path) -> dict[str, list[str]]:
    """Edge path (relative to `run`) -> its vector columns, from the sidecars under results/."""
    out = {}
    for side in sorted((run / "results").rglob("*.sha256.json")):
        try:
            vectors = json.loads(side.read_text()).get("vectors") or {}
        except json.JSONDecodeError:
            continue
        if vectors:
            edge = side.with_name(side.name[: -len(".sha256.json")])
            out[edge.relative_to(run).as_posix()] = sorted(vectors)
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


def _column_difference(run_a: Path, run_b: Path, edge: str, column: str) -> EdgeDifference:
    ids_a, a = edges.read_vectors(run_a / edge, column)
    try:
        ids_b, b = edges.read_vectors(run_b / edge, column)
    except edges.EdgeError as exc:
        return EdgeDifference(edge, column, len(ids_a), math.inf, note=f"run b: {exc}")
    if set(ids_a) != set(ids_b):
        only = sorted(set(ids_a) ^ set(ids_b))
        return EdgeDifference(
            edge, column, len(ids_a), math.inf, note=f"keys differ ({len(only)}, e.g. {only[0]!r})"
        )
    if a.shape[1] != b.shape[1]:
        return EdgeDifference(
            edge, column, len(ids_a), math.inf, note=f"dimension {a.shape[1]} vs {b.shape[1]}"
        )
    if not len(ids_a):
        return EdgeDifference(edge, column, 0, 0.0)
    where = {k: i for i, k in enumerate(ids_b)}
    rel = relative_row_differences(a, b[[where[k] for k in ids_a]])
    worst = int(np.argmax(rel))
    return EdgeDifference(edge, column, len(ids_a), float(rel[worst]), str(ids_a[worst]))


def vector_edge_differences(run_a: str | Path, run_b: str | Path) -> list[EdgeDifference]:
    """Every vector column of every vector edge of run `run_a` (a workflow directory with
    results/) against the same edge of `run_b`, rows joined on the key; an edge `run_b` lacks
    (or with other keys or dimensions) has an infinite difference and a note. Edges only
    `run_b` has are listed too."""
    run_a, run_b = Path(run_a), Path(run_b)
    in_a, in_b = _vector_edges(run_a), _vector_edges(run_b)
    out = [
        _column_difference(run_a, run_b, edge, column)
        for edge, columns in in_a.items()
        for column in columns
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
    """Per stage (sorted), the largest relative difference of its vector edges between the two
    runs (`vector_edge_differences`), with its tolerance (`tolerances`, by default
    `STAGE_TOLERANCES`; `DEFAULT_TOLERANCE` for a stage not named)."""
    tolerances = STAGE_TOLERANCES if tolerances is None else tolerances
    by_stage: dict[str, list[EdgeDifference]] = {}
    for diff in vector_edge_differences(run_a, run_b):
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


def compare_decisions(run_a: str | Path, run_b: str | Path) -> DecisionComparison | None:
    """The findings' decisions (`DECISIONS`: one row per decision the findings page states,
    keyed by `decision_id`, its verdict in `decision`) of both runs compared; None where a run
    did not produce the edge."""
    paths = [Path(run_a) / DECISIONS, Path(run_b) / DECISIONS]
    if not all(p.exists() for p in paths):
        return None
    a, b = (
        dict(zip(e.frame["decision_id"], e.frame["decision"].astype(str), strict=True))
        for e in (edges.read(p, columns=["decision_id", "decision"]) for p in paths)
    )
    return DecisionComparison(
        decisions=len(a),
        differ=tuple(sorted(k for k in a.keys() & b.keys() if a[k] != b[k])),
        only_a=tuple(sorted(a.keys() - b.keys())),
        only_b=tuple(sorted(b.keys() - a.keys())),
    )
