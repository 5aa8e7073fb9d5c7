"""Two runs compared (tacgen_lib.io.run_compare): the relative difference of each vector edge's
rows joined on the key, the largest per stage against its tolerance, what cannot be compared,
and the findings' decisions; and docs/cluster.md states the tolerances the module holds."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tacgen_lib.io import edges
from tacgen_lib.io.run_compare import (
    DECISIONS,
    DEFAULT_TOLERANCE,
    STAGE_TOLERANCES,
    compare_decisions,
    edge_differences,
    relative_column_differences,
    relative_row_differences,
    stage_differences,
)

ROOT = Path(__file__).resolve().parents[2]
IDS = np.array([f"s-{i:03d}" for i in range(6)], dtype=object)


def _write(run: Path, rel: str, ids, **vectors) -> None:
    path = run / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    edges.write_vectors(path, ids, vectors, producer="test")


@pytest.fixture
def runs(tmp_path):
    """Two runs: features equal, align's rows in another order with one row moved, a table
    without vectors, and a policy edge only run a has."""
    rng = np.random.default_rng(0)
    vit, t = rng.normal(size=(6, 4)), rng.normal(size=(6, 3))
    a, b = tmp_path / "a", tmp_path / "b"
    for run in (a, b):
        _write(run, "results/features/c/vision.parquet", IDS, vit=vit)
        frame = pd.DataFrame({"cell": ["x"], "score": [0.5]})
        (run / "results/align").mkdir(parents=True, exist_ok=True)
        edges.write(run / "results/align/summary.parquet", frame, key="cell", producer="test")
    _write(a, "results/align/c/aligned.parquet", IDS, t_aligned=t)
    moved = t.copy()
    moved[2] = moved[2] * 1.01  # |a - b| / max(|a|, |b|) = 0.01 / 1.01
    order = np.arange(6)[::-1]
    _write(b, "results/align/c/aligned.parquet", IDS[order], t_aligned=moved[order])
    _write(a, "results/policy/palpation.parquet", IDS, v=vit)
    return a, b


def test_the_relative_difference_of_rows():
    a = np.array([[3.0, 4.0], [0.0, 0.0], [1.0, 0.0]])
    b = np.array([[3.0, 4.0], [0.0, 0.0], [0.0, 2.0]])
    got = relative_row_differences(a, b)
    np.testing.assert_allclose(got, [0.0, 0.0, math.sqrt(5) / 2])
    # the scale of the features does not matter
    np.testing.assert_allclose(relative_row_differences(a * 1e6, b * 1e6), got)


def test_the_relative_difference_of_a_scalar_column():
    a = np.array([1.0, -2.0, np.nan, 0.5, np.nan])
    b = np.array([1.0, -1.0, np.nan, 0.5, 3.0])
    got = relative_column_differences(a, b)
    np.testing.assert_allclose(got[:4], [0.0, 0.5, 0.0, 0.0])  # on the column's scale, 2
    assert math.isinf(got[4])  # NaN in one run only
    np.testing.assert_allclose(relative_column_differences(a[:2] * 1e-6, b[:2] * 1e-6), got[:2])
    assert not relative_column_differences(np.zeros(3), np.zeros(3)).any()


def test_each_vector_and_float_column_is_compared_on_its_key(runs):
    a, b = runs
    found = {(d.edge, d.column): d for d in edge_differences(a, b)}
    assert set(found) == {
        ("results/features/c/vision.parquet", "vit"),
        ("results/align/c/aligned.parquet", "t_aligned"),
        ("results/align/summary.parquet", "score"),
        ("results/policy/palpation.parquet", "v"),
    }  # the summary table's float column too, its string key not
    assert found["results/align/summary.parquet", "score"].max_rel == 0.0
    assert found["results/features/c/vision.parquet", "vit"].max_rel == 0.0
    align = found["results/align/c/aligned.parquet", "t_aligned"]
    assert align.max_rel == pytest.approx(0.01 / 1.01, rel=1e-5)  # joined on the key
    assert (align.worst_key, align.rows, align.stage) == ("s-002", 6, "align")
    policy = found["results/policy/palpation.parquet", "v"]
    assert math.isinf(policy.max_rel) and "run b" in policy.note


def test_the_largest_per_stage_against_its_tolerance(runs):
    a, b = runs
    stages = {s.stage: s for s in stage_differences(a, b)}
    assert list(stages) == ["align", "features", "policy"]
    assert stages["align"].within and stages["align"].tolerance == STAGE_TOLERANCES["align"]
    assert stages["features"].max_rel == 0.0 and stages["features"].within
    assert not stages["policy"].within  # missing in run b
    tight = {s.stage: s for s in stage_differences(a, b, {"align": 1e-3})}
    assert not tight["align"].within and tight["features"].tolerance == DEFAULT_TOLERANCE


def test_what_cannot_be_compared_is_said(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    rng = np.random.default_rng(1)
    _write(a, "results/features/c/vision.parquet", IDS, vit=rng.normal(size=(6, 4)))
    _write(b, "results/features/c/vision.parquet", IDS[:5], vit=rng.normal(size=(5, 4)))
    _write(a, "results/generate/c/t_gen.parquet", IDS, t_gen=rng.normal(size=(6, 4)))
    _write(b, "results/generate/c/t_gen.parquet", IDS, t_gen=rng.normal(size=(6, 5)))
    _write(b, "results/pixel/c/frames.parquet", IDS, vit=rng.normal(size=(6, 4)))
    notes = {d.stage: d.note for d in edge_differences(a, b)}
    assert "keys differ (1, e.g. 's-005')" in notes["features"]
    assert "dimension 4 vs 5" in notes["generate"]
    assert notes["pixel"] == "only in run b"
    assert not any(s.within for s in stage_differences(a, b))


def _decisions(run: Path, rows: dict[str, str]) -> None:
    frame = pd.DataFrame(
        {
            "decision_id": list(rows),
            "what": ["w"] * len(rows),
            "value": [0.1] * len(rows),
            "ci_low": [0.0] * len(rows),
            "ci_high": [0.2] * len(rows),
            "threshold": [0.0] * len(rows),
            "decision": list(rows.values()),
        }
    )
    (run / DECISIONS).parent.mkdir(parents=True, exist_ok=True)
    edges.write(run / DECISIONS, frame, key="decision_id", producer="findings")


def test_the_findings_decisions_are_compared_by_id(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert compare_decisions(a, b) is None  # not produced
    _decisions(a, {"touch_helps": "yes", "null_control": "no", "policy": "yes"})
    assert compare_decisions(a, b) is None  # one run only
    _decisions(b, {"touch_helps": "yes", "null_control": "no", "policy": "yes"})
    same = compare_decisions(a, b)
    assert same.agree and same.decisions == 3
    _decisions(b, {"touch_helps": "no", "null_control": "no", "regime": "yes"})
    other = compare_decisions(a, b)
    assert not other.agree
    assert (other.differ, other.only_a, other.only_b) == (
        ("touch_helps",),
        ("policy",),
        ("regime",),
    )
    assert other.lines[0] == "touch_helps: a yes (0.1 [0, 0.2]); b no (0.1 [0, 0.2])"
    assert other.lines[1].startswith("policy: a yes") and other.lines[1].endswith("b not stated")


def test_docs_state_the_tolerances_the_module_holds():
    """docs/cluster.md's table of stage tolerances is STAGE_TOLERANCES, and the default."""
    text = (ROOT / "docs" / "cluster.md").read_text()
    section = text[text.index("### Checking a GPU against the CPU") :]
    rows = dict(re.findall(r"^\| `(\w+)` \| ([\d.]+) \|", section, re.M))
    assert {k: float(v) for k, v in rows.items()} == STAGE_TOLERANCES
    other = re.search(r"^\| any other \| ([\d.]+) \|", section, re.M)
    assert other and float(other.group(1)) == DEFAULT_TOLERANCE
