"""tools/device_check.py, the GPU-against-CPU check, without a GPU: its run mode (two copies of
the workflow, one per device, here a dry run each), its comparison of two finished runs (exit
0 within every tolerance, 1 past one), and on the test session's CPU run of config/test.yaml
against a copy with one feature edge moved: the features stage is named, every other stage is
equal in every row."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from snakemake_run import copy_run

from tacgen_lib.io import edges

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = [sys.executable, str(ROOT / "tools" / "device_check.py")]


def check(*args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*SCRIPT, *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT
    )


def _move_rows(path: Path, column: str, factor: float, rows: int = 1) -> None:
    """Rewrite a vector edge (with its sidecar) with its first `rows` rows scaled."""
    ids, vectors = edges.read_vectors(path, column)
    vectors = vectors.astype(np.float64)
    vectors[:rows] *= factor
    edges.write_vectors(path, ids, {column: vectors}, producer="test")


def test_two_finished_runs_are_compared(tmp_path):
    ids = np.array([f"s-{i}" for i in range(4)], dtype=object)
    for run in ("a", "b"):
        path = tmp_path / run / "results/align/c/aligned.parquet"
        path.parent.mkdir(parents=True)
        edges.write_vectors(path, ids, {"t_aligned": np.ones((4, 3))}, producer="test")
    same = check("--compare", str(tmp_path / "a"), str(tmp_path / "b"))
    assert same.returncode == 0, same.stdout + same.stderr
    assert "align" in same.stdout and "equal in every row" in same.stdout
    assert "decisions: not produced by this run" in same.stdout
    assert "device check: ok" in same.stdout
    _move_rows(tmp_path / "b/results/align/c/aligned.parquet", "t_aligned", 2.0)
    moved = check("--compare", str(tmp_path / "a"), str(tmp_path / "b"))
    assert moved.returncode == 1
    line = next(x for x in moved.stdout.splitlines() if x.startswith("align"))
    assert " 0.5 " in line and " NO " in line and "'s-0'" in line, line
    assert "device check: FAILED" in moved.stdout


def test_the_run_mode_makes_one_copy_per_device(tmp_path):
    """Both runs with their device (a dry run each: Snakemake arguments after --)."""
    got = check("--devices", "cpu", "cpu", "--work", str(tmp_path), "--", "--dry-run")
    assert got.returncode == 0, got.stdout + got.stderr
    for name in ("cpu-1", "cpu-2"):
        log = (tmp_path / name / "device_check.log").read_text()
        assert "This was a dry-run" in log, log[-2000:]
        assert (tmp_path / name / "Snakefile").exists()
    assert "device cpu: config/test.yaml in" in got.stdout
    assert "no vector edges in either run" in got.stdout


@pytest.mark.workflow
def test_the_check_on_two_cpu_runs_of_config_test(reference_run, tmp_path):
    other = copy_run(reference_run, tmp_path / "other")
    feature = sorted((other / "results/features").rglob("vision.parquet"))[0]
    _move_rows(feature, "vit", 1.5, rows=2)
    got = check("--compare", str(reference_run), str(other))
    assert got.returncode == 1, got.stdout + got.stderr
    table = {
        line.split()[0]: line for line in got.stdout.splitlines() if line and line[0].islower()
    }
    assert {"align", "features", "generate", "pixel", "policy"} <= set(table), got.stdout
    assert " NO " in table["features"] and str(feature.relative_to(other)) in table["features"]
    for stage in ("align", "generate", "pixel", "policy"):
        assert "equal in every row" in table[stage], table[stage]
    assert "decisions:" in got.stdout
