"""The knob table (tacgen_lib.cost.knobs) and the readers of a setting's edges
(tacgen_lib.cost.readers): settings, module configs, moved paths (equal to Snakemake's own
`replace_prefix`), replicate seeds and the headline probe row."""

from pathlib import Path

import pandas as pd
import pytest
from snakemake.path_modifier import PathModifier
from snakemake_run import validated

from tacgen_lib.cost.knobs import (
    KNOBS,
    UnknownKnobError,
    knob_bootstrap,
    knob_metrics,
    knob_settings,
    moved_path,
    setting_label,
    shared_runs,
)
from tacgen_lib.cost.readers import READERS, headline_row
from tacgen_lib.estimate.dag import base_rule
from tacgen_lib.io.config import load_yaml

ROOT = Path(__file__).resolve().parents[2]
#: the embedded default as the cost rules read it: validated, the schema's defaults filled in
CONFIG = validated()
COST = load_yaml(ROOT / "config" / "cost.yaml")["cost"]


def _get(config, dotted):
    node = config
    for part in dotted.split("."):
        node = node[part]
    return node


def test_every_swept_knob_names_existing_keys_a_reader_and_rules():
    ctx = {"sim": COST["sim_sweep"]["corpus"]}
    for name, knob in KNOBS.items():
        assert knob.reads in READERS, name
        if knob.free:  # its keys are the stage grid it reads
            assert knob.keys and not knob.reruns and not knob.moves, name
            for key in knob.keys:
                _get(CONFIG, key)
            continue
        assert knob.reruns and knob.moves, name
        for key in knob.keys:
            _get(CONFIG, key.removesuffix("[]").format(**ctx))  # a key of the default config
        assert all(m.startswith("results/") and m.endswith("/") for m in knob.moves), name


def test_cost_yaml_sweeps_only_table_knobs_and_each_has_one_default():
    for name, entry in COST["knobs"].items():
        runs = knob_settings(name, entry, {**CONFIG, "cost": COST})
        assert len(runs) == len(entry["values"]) * (
            int(entry.get("replicates", 5)) if KNOBS[name].replicate_key else 1
        )
        defaults = {r.label for r in runs if r.is_default}
        assert len(defaults) == (0 if name == "align_steps" else 1), (name, defaults)


def test_a_setting_sets_its_keys_and_nothing_else_of_the_run():
    config = {**CONFIG, "cost": COST}
    (run,) = [r for r in knob_settings("backbone_arch", {"values": ["vit_small"]}, config)]
    cfg = run.config
    assert cfg["features"]["backbones"]["tactile"]["arch"] == "vit_small"
    assert cfg["features"]["backbones"]["vision"] == CONFIG["features"]["backbones"]["vision"]
    assert cfg["cost"] == {
        "knobs": {},
        "grid_knobs": False,
        "setting": {
            "knob": "backbone_arch",
            "label": "vit_small",
            "rep": 0,
            "module": "cost_backbone_arch_vit_small",
        },
    }
    # everything else is the run's own config, which is left untouched
    assert {k: v for k, v in cfg.items() if k not in ("features", "cost")} == {
        k: v for k, v in config.items() if k not in ("features", "cost")
    }
    assert CONFIG["features"]["backbones"]["tactile"]["arch"] == "vit_tiny"
    assert run.root == "results/cost/backbone_arch/vit_small/"
    assert run.number == 384.0 and not run.is_default


def test_list_keys_fixed_keys_and_the_reduced_corpus():
    config = {**CONFIG, "cost": COST}
    n = {r.label: r for r in knob_settings("align_n", {"values": [100, "all"]}, config)}
    assert n["100"].config["align"]["n_train"] == [100]
    assert n["100"].config["probes"]["heads"]["n_train"] == 100
    assert n["all"].is_default and not n["100"].is_default
    steps = knob_settings("align_steps", {"values": [900]}, config)[0]
    assert steps.config["align"]["budget"] == "steps" and steps.config["align"]["steps"] == 900
    tac = knob_settings("tactile_resolution", {"values": [[60, 80], [120, 160]]}, config)
    sim, n_sim = COST["sim_sweep"]["corpus"], COST["sim_sweep"]["n"]
    assert [r.label for r in tac] == ["60x80", "120x160"]
    assert [r.number for r in tac] == [60.0, 120.0]
    assert [r.is_default for r in tac] == [False, True]
    corpus = tac[0].config["corpora"][sim]
    assert corpus["tactile_size"] == [60, 80] and corpus["n"] == n_sim and corpus["shards"] == 1


def test_replicates_vary_the_resample_seed_from_the_run_s_probe_seed():
    config = {**CONFIG, "cost": COST}
    runs = knob_settings("probe_bootstrap", {"values": [200, 5000], "replicates": 3}, config)
    seed = CONFIG["probes"]["seeds"][0]
    assert [(r.label, r.rep) for r in runs] == [(v, k) for v in ("200", "5000") for k in range(3)]
    assert [r.config["probes"]["resample_seed"] for r in runs[:3]] == [seed, seed + 1, seed + 2]
    assert [r.config["probes"]["bootstrap"] for r in runs] == [200] * 3 + [5000] * 3
    assert len({r.module for r in runs}) == 6  # one module each
    assert runs[3].is_default and runs[3].root == "results/cost/probe_bootstrap/5000/rep~0/"


def test_unknown_free_and_empty_knobs_are_refused():
    with pytest.raises(UnknownKnobError, match="'align_stepz'.*align_steps"):
        knob_settings("align_stepz", {"values": [1]}, CONFIG)
    with pytest.raises(ValueError, match=r"stage's own grid \(generate\.samplers\)"):
        knob_settings("generate_steps", {"values": [5]}, CONFIG)
    assert knob_settings("policy_width", {}, CONFIG) == []
    with pytest.raises(ValueError, match="no values"):
        knob_settings("image_size", {}, CONFIG)


@pytest.mark.parametrize(
    "path",
    [
        "results/align/{corpus}/{variant}/seed~{seed}/tau~{tau}/n~{n_train}/metrics.parquet",
        "results/features/backbones/{modality}.pt",
        "results/features/{corpus}/vision.parquet",
        "results/corpus/splits.parquet",
        "results/benchmarks/train_heads/{corpus}.tsv",
        "results/logs/probe/{family}.log",
        "results/report/cost_of_accuracy.html",
        "config/scenes.yaml",
        "/abs/results/align/x.parquet",
    ],
)
def test_moved_path_is_snakemake_s_replace_prefix(path):
    for name, entry in COST["knobs"].items():
        run = knob_settings(name, entry, {**CONFIG, "cost": COST})[0]
        snakemake_path = PathModifier(run.replace_prefix, None, None).replace_prefix(path)
        assert moved_path(path, run.replace_prefix) == snakemake_path, (name, path)


def test_moved_path_refuses_ambiguous_prefixes():
    with pytest.raises(ValueError, match="ambiguous"):
        moved_path("results/a/b.tsv", {"results/a/": "x/", "results/a/b": "y/"})


def test_base_rule_strips_the_module_prefix_only_inside_a_setting():
    run = knob_settings("image_size", {"values": [28]}, CONFIG)[0]
    assert base_rule(f"{run.module}_pretrain_backbone", run.config) == "pretrain_backbone"
    assert base_rule("cost_image_size_28_x", CONFIG) == "cost_image_size_28_x"


def test_labels_metrics_and_bootstrap():
    assert setting_label([120, 160]) == "120x160" and setting_label(300) == "300"
    assert setting_label(2.0) == "2" and setting_label("all") == "all"
    targets = CONFIG["features"]["pretrained_vs_random"]["targets"]
    assert knob_metrics(KNOBS["image_size"], CONFIG) == [
        f"vision {targets['vision']} accuracy",
        f"tactile {targets['tactile']} accuracy",
    ]
    assert knob_metrics(KNOBS["align_n"], CONFIG) is None  # the reader's own metrics
    assert knob_bootstrap(KNOBS["align_n"], {}, CONFIG) == 2000
    assert knob_bootstrap(KNOBS["align_n"], {"bootstrap": 300}, CONFIG) == 300
    assert knob_bootstrap(KNOBS["presses"], {}, CONFIG) == CONFIG["probes"]["bootstrap"]


def test_headline_row_is_raw_concat_at_the_heads_variant():
    base = {
        "family": "force",
        "input": "raw",
        "fusion": "concat",
        "t_variant": "clip128",
        "heads_variant": "clip128",
        "control": "none",
        "delta": 0.5,
    }
    rows = pd.DataFrame(
        [
            base,
            {**base, "fusion": "mean", "delta": 0.1},
            {**base, "t_variant": "clahe", "delta": 0.2},
            {**base, "input": "aligned", "delta": 0.3},
            {**base, "control": "tactile_permutation", "delta": -0.1},
        ]
    )
    assert headline_row(rows)["delta"] == 0.5
    assert headline_row(rows, "tactile_permutation")["delta"] == -0.1
    with pytest.raises(ValueError, match="0 headline rows"):
        headline_row(rows.assign(heads_variant="histmatch"))


def test_the_validated_config_has_what_the_knobs_read():
    # the knobs read the run's own value from the validated config (rules/cost_common.smk):
    # config.yaml or the schema's default
    sim = COST["sim_sweep"]["corpus"]
    assert CONFIG["corpora"][sim]["tactile_size"] and CONFIG["corpora"][sim]["presses"]


def test_a_setting_that_is_another_knob_s_run_is_run_once():
    config = {**CONFIG, "cost": COST}
    runs = shared_runs(
        knob_settings("image_size", {"values": [28, 56]}, config)
        + knob_settings("pretrain_epochs", {"values": [0, 2]}, config)
        + knob_settings("presses", {"values": [8]}, config)
        + knob_settings("tactile_resolution", {"values": [[120, 160]]}, config)
    )
    by = {(r.knob, r.label): r for r in runs}
    # image size 56 and pretraining epochs 0 are both the run's own features: one run
    assert by[("pretrain_epochs", "0")].module == by[("image_size", "56")].module
    assert by[("pretrain_epochs", "0")].root == "results/cost/image_size/56/"
    assert by[("pretrain_epochs", "0")].is_default and by[("image_size", "56")].is_default
    assert by[("pretrain_epochs", "2")].module == "cost_pretrain_epochs_2"
    # the two simulation knobs' defaults are one reduced corpus
    assert by[("tactile_resolution", "120x160")].module == by[("presses", "8")].module
    # the same config with other folders moved is another run
    features_default = by[("image_size", "56")]
    assert features_default.module != by[("presses", "8")].module
    assert len({r.module for r in runs}) == 4
