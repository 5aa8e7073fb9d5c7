"""The knob sweep runs end to end on the tiny config (config/cost_tiny.yaml over test.yaml), on
a copy of the session's reference run, so only the sweep's own jobs run (~30-60 s). Each setting
is the main rules again under the setting's config (a module per setting): at the run's own
setting they write the main run's edges bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
import yaml
from snakemake_run import copy_run, copy_tree, plan_of, planned_rules, report_page, smk

from tacgen_lib.cost.points import read_points

pytestmark = pytest.mark.workflow

SWEEP = ("--configfile", "config/test.yaml", "config/cost_tiny.yaml")


def test_default_config_runs_no_sweep_job(cold_dry_run):
    rules = plan_of(cold_dry_run)  # a fresh copy of the repository (conftest)
    assert "cost_of_accuracy" in rules
    assert not [r for r in rules if r.startswith(("cost_align", "cost_probe"))]  # no setting
    # the free knobs (the stages' own grids) still give the page its points, through the same
    # rule as a swept knob: 2 generator, 2 policy knobs and the backbone families (config/
    # test.yaml runs three)
    assert rules.get("cost_knob_points") == 5


def test_unknown_knob_stops_with_the_known_names(tmp_path):
    work = copy_tree(tmp_path / "bad")
    (work / "config" / "bad_cost.yaml").write_text(
        yaml.safe_dump({"cost": {"knobs": {"align_stepz": {"values": [1, 2]}}}})
    )
    proc = smk(
        work,
        "--dry-run",
        "--configfile",
        "config/test.yaml",
        "config/bad_cost.yaml",
        "--",
        "cost_of_accuracy",
        check=False,
    )
    assert proc.returncode != 0
    assert "'align_stepz' is not a knob" in proc.stdout + proc.stderr
    assert "align_steps" in proc.stdout + proc.stderr


def test_tiny_sweep_writes_points_and_the_page(reference_run: Path, tmp_path):
    work = copy_run(reference_run, tmp_path / "sweep")
    planned = planned_rules(work, *SWEEP, "--", "cost_of_accuracy")
    heads = [r for r in planned if r.startswith("cost_align") and r.endswith("_train_heads")]
    probes = [r for r in planned if r.startswith("cost_probe") and r.endswith("_probe")]
    assert len(heads) == 4  # 2 knobs x 2 settings (1 seed): the main rule, one module each
    # 2 knobs x 2 settings x 2 replicates, but both knobs' own defaults (B = 200 resamples,
    # 10 permutations: test.yaml's) are one run
    assert len(probes) == 6
    assert not [r for r in probes if r.startswith("cost_probe_permutations_10_")]
    assert all(planned[r] == 1 for r in heads + probes)
    assert "train_heads" not in planned and "probe" not in planned  # the default's jobs stay
    smk(work, *SWEEP, "--", "cost_of_accuracy")
    points = {
        k: read_points(work / f"results/cost/points/{k}.parquet")
        for k in (
            "align_steps",
            "align_n",
            "probe_bootstrap",
            "probe_permutations",
            "generate_steps",
            "generate_sampler",
            "policy_width",
            "policy_epochs",
            "backbones",
        )
    }
    for knob, p in points.items():
        assert (p["knob"] == knob).all()
        assert (p["wall_s"] > 0).all(), knob
        assert p["n_jobs"].min() >= 1
    n = points["align_n"]
    assert sorted(set(n["label"])) == ["10", "all"]
    assert n.loc[n["label"] == "all", "is_default"].all()  # the default's heads use all rows
    assert set(n["direction"]) == {"higher", "lower"}  # top-1 up, median rank down
    b = points["probe_bootstrap"]
    assert set(b["label"]) == {"100", "200"} and b["value"].notna().all()
    assert b.loc[b["label"] == "200", "is_default"].all()  # test.yaml's probes.bootstrap
    # at the run's own setting a knob's main rule writes the main run's edge, bit for bit
    same = {
        "results/align/sim_paired/clip128/seed~42/tau~0.07/n~all/metrics.parquet": "results/cost/align_n/all/align/sim_paired/clip128/seed~42/tau~0.07/n~all/"
        "metrics.parquet",
        "results/probes/force/protocol~raw/seed~42.parquet": "results/cost/probe_bootstrap/200/rep~0/probes/force/protocol~raw/seed~42.parquet",
    }
    for main, setting in same.items():
        assert _sha(work / main) == _sha(work / setting), (main, setting)
    # a setting's seconds are its own jobs' benchmark files, every one of them
    for knob in ("align_n", "probe_bootstrap"):
        p = points[knob]
        files = sorted((work / "results/cost" / knob).glob("**/benchmarks/**/*.tsv"))
        per_label = p.groupby("label")["n_jobs"].first()
        assert per_label.sum() == len(files), (knob, per_label.to_dict(), len(files))
    perm = points["probe_permutations"]
    res = perm[perm["metric"].str.contains("resolution")].set_index("label")["value"]
    assert res.to_dict() == pytest.approx({"5": 1 / 6, "10": 1 / 11})
    page = report_page(work / "results/report/cost_of_accuracy.html")
    assert "align_steps: " in page and "probe_permutations: " in page
    figures = sorted((work / "results/report/cost_of_accuracy").glob("*.png"))
    assert figures and all(f.stat().st_size > 5_000 for f in figures)  # one figure per knob
    table = pd.read_csv(work / "results/report/cost_of_accuracy.tsv", sep="\t")
    assert set(table["knob"]) == set(points)
    again = planned_rules(work, *SWEEP, "--", "cost_of_accuracy")
    assert again == {}, again  # a second run has nothing to do


def _sha(path: Path) -> str:
    """The SHA-256 of an edge's data, from its sidecar."""
    return json.loads(Path(f"{path}.sha256.json").read_text())["sha256"]
