"""The simulation and features knob sweeps run end to end on a tiny config: each setting is the
main rules again under its config (a module per setting, tacgen_lib.cost.knobs), every point
file obeys the contract, its seconds are its own jobs' benchmark files (all of them), the
epochs-0 backbone is the seeded random init (Delta pretrained - random is exactly 0), and at the
run's own setting the features knobs write the main run's edges bit for bit.

It runs on a copy of the session's reference run of config/test.yaml (conftest.reference_run),
so only the settings' jobs run here."""

import json
import re
import subprocess

import pandas as pd
import yaml
from snakemake_run import SNAKEMAKE, copy_run

from tacgen_lib.cost.knobs import KNOBS, knob_metrics
from tacgen_lib.cost.points import check_points

TINY_COST = {
    "cost": {
        "knobs": {
            "presses": {"values": [2, 3]},  # test.yaml's sim_paired has 3 presses
            # test.yaml's only: the same run as presses 3 (each sim setting is the pipeline
            # again; presses 2 runs the non-default one, through the same module machinery)
            "tactile_resolution": {"values": [[120, 160]]},
            "image_size": {"values": [28]},  # test.yaml's: each knob's default runs once
            "backbone_arch": {"values": ["vit_tiny"]},
            "pretrain_epochs": {"values": [0, 1]},  # test.yaml: 1 (the DINO path stays tested)
        },
        "sim_sweep": {"corpus": "sim_paired", "n": 24},
    }
}
KNOBS_RUN = list(TINY_COST["cost"]["knobs"])


def test_knob_sweeps_run_on_the_tiny_config(reference_run, tmp_path):
    work = copy_run(reference_run, tmp_path / "run")
    (work / "config" / "cost_tiny.yaml").write_text(yaml.safe_dump(TINY_COST, sort_keys=False))
    targets = [f"results/cost/points/{k}.parquet" for k in KNOBS_RUN]
    cmd = [
        *SNAKEMAKE,
        "--cores",
        "2",
        "--configfile",
        "config/test.yaml",
        "config/cost_tiny.yaml",
        "--",
        *targets,
    ]
    proc = subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-6000:]
    # only the sweep's own jobs ran: the reference run's upstream edges were reused as they are
    ran = set(re.findall(r"(?m)^(?:local)?rule (\w+):", proc.stdout + proc.stderr))
    assert ran and all(rule.startswith("cost_") for rule in ran), sorted(ran)
    config = yaml.safe_load((work / "config" / "config.yaml").read_text())
    for knob in KNOBS_RUN:
        points = check_points(pd.read_parquet(work / f"results/cost/points/{knob}.parquet"), knob)
        values = TINY_COST["cost"]["knobs"][knob]["values"]
        assert points["label"].nunique() == len(values)
        assert list(points["metric"].unique()) == knob_metrics(KNOBS[knob], config)
        assert (points["wall_s"] > 0).all() and (points["n_jobs"] >= 5).all()
        assert points.groupby("label")["is_default"].first().sum() == 1  # each holds test.yaml's
        # the seconds sum every job the setting ran: one benchmark file each
        for label, n_jobs in points.groupby("label")["n_jobs"].first().items():
            folder = work / "results/cost" / knob / label / "benchmarks"
            if folder.exists():  # else the same run as another knob's setting
                assert n_jobs == len(list(folder.glob("**/*.tsv"))), (knob, label, n_jobs)
    # a setting that is another knob's run ran once: each knob's own default
    for knob, label in (
        ("tactile_resolution", "120x160"),
        ("backbone_arch", "vit_tiny"),
        ("pretrain_epochs", "1"),
    ):
        assert not (work / "results/cost" / knob / label).exists(), (knob, label)
    # at test.yaml's own image size the features rules write the main run's edges
    for edge in (
        "pretrained_vs_random.parquet",
        "backbones/vision.pt",
        "sim_paired/vision.parquet",
    ):
        main = work / "results/features" / edge
        setting = work / "results/cost/image_size/28/features" / edge
        assert _sha(main) == _sha(setting), edge
    epochs = pd.read_parquet(work / "results/cost/points/pretrain_epochs.parquet")
    # at 0 DINO epochs the tactile ViT is its random init: pretrained - random is 0 by
    # construction (the vision side is SimCLR-pretrained at any DINO epochs, so it is not)
    at_zero = epochs[(epochs["label"] == "0") & epochs["metric"].str.startswith("tactile")]
    assert len(at_zero) == 1
    assert (at_zero[["value", "ci_low", "ci_high"]] == 0).all().all()
    # a second run has nothing to do
    again = subprocess.run(
        [*cmd[: -len(targets) - 1], "--dry-run", "--", *targets],
        cwd=work,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert "Nothing to be done" in again.stdout + again.stderr


def _sha(path) -> str:
    """The SHA-256 of an edge (or weights file), from its sidecar."""
    return json.loads(path.with_name(path.name + ".sha256.json").read_text())["sha256"]
