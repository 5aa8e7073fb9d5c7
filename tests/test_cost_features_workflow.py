"""The simulation and features knob sweeps (rules/cost_features.smk) run end to end on a tiny
config (5 settings, 28 jobs: a setting shared by two knobs runs once): every point file obeys
the contract, its seconds come from benchmark files, and the epochs-0 backbone is the seeded
random init (Delta pretrained - random is exactly 0).

It runs on a copy of the session's reference run of config/test.yaml (conftest.reference_run):
the sweeps read its splits, backbones and preprocessed frames, and every seconds figure sums
the sweep's own jobs' benchmark files (cost_*), so only the sweep's jobs run here."""

import re
import subprocess

import pandas as pd
import yaml
from snakemake_run import SNAKEMAKE, copy_run

from tacgen_lib.cost.knob_metrics import knob_metric_ids
from tacgen_lib.cost.points import check_points

TINY_COST = {
    "cost": {
        "knobs": {
            "presses": {"values": [2, 3]},  # test.yaml's sim_paired has 3 presses
            "tactile_resolution": {"values": [[60, 80], [120, 160]]},
            "image_size": {"values": [28]},  # test.yaml's: settings are shared between knobs
            "backbone_arch": {"values": ["vit_tiny"]},
            "pretrain_epochs": {"values": [0, 1]},  # test.yaml: 1 (the DINO path stays tested)
        },
        "sim_sweep": {"corpus": "sim_paired", "n": 24},
    }
}
KNOBS = list(TINY_COST["cost"]["knobs"])


def test_knob_sweeps_run_on_the_tiny_config(reference_run, tmp_path):
    work = copy_run(reference_run, tmp_path / "run")
    (work / "config" / "cost_tiny.yaml").write_text(yaml.safe_dump(TINY_COST))
    cmd = [*SNAKEMAKE, "--cores", "2", "--configfile", "config/test.yaml",
           "config/cost_tiny.yaml", "--", "cost_features_knobs"]  # fmt: skip
    proc = subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-6000:]
    # only the sweep's own jobs ran: the reference run's upstream edges were reused as they are
    ran = set(re.findall(r"(?m)^(?:local)?rule (\w+):", proc.stdout + proc.stderr))
    assert ran and all(rule.startswith("cost_") for rule in ran), sorted(ran)
    config = yaml.safe_load((work / "config" / "config.yaml").read_text())
    for knob in KNOBS:
        points = check_points(pd.read_parquet(work / f"results/cost/points/{knob}.parquet"), knob)
        values = TINY_COST["cost"]["knobs"][knob]["values"]
        assert points["label"].nunique() == len(values)
        assert list(points["metric"].unique()) == knob_metric_ids(knob, config)
        assert (points["wall_s"] > 0).all() and (points["n_jobs"] >= 5).all()
        assert points.groupby("label")["is_default"].first().sum() == 1  # each holds test.yaml's
    epochs = pd.read_parquet(work / "results/cost/points/pretrain_epochs.parquet")
    at_zero = epochs[epochs["label"] == "0"]
    assert (at_zero[["value", "ci_low", "ci_high"]] == 0).all().all()
    # a second run has nothing to do
    again = subprocess.run([*cmd[:-2], "--dry-run", "--", "cost_features_knobs"], cwd=work,
                           capture_output=True, text=True, timeout=300)  # fmt: skip
    assert "Nothing to be done" in again.stdout + again.stderr
