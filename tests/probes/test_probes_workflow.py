"""The probes stage in the workflow (rules probe, aggregate_probes) on config/test.yaml.

The run writes synthetic upstream edges with `tacgen_lib.io.edges` (manifest, splits, vision and
tactile features per preprocessing variant, aligned projections per alignment seed) and allows
only the probe rules, so it takes seconds; tests/test_workflow.py runs the whole DAG. In the
synthetic corpora the tactile features carry the labels on the paired and controlled corpora
and nothing on the null corpus, so the summary must show V+T beating V there and not here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from snakemake_run import copy_tree, merged_config, report_page, smk, validated

from tacgen_lib.io import edges  # noqa: E402
from tacgen_lib.probes.compare import CONTROLS  # noqa: E402
from tacgen_lib.probes.protocol import tidy  # noqa: E402
from tacgen_lib.report import probe_figures  # noqa: E402

pytestmark = pytest.mark.workflow

PROBE_RULES = [
    "--allowed-rules",
    "probe",
    "aggregate_probes",
    "probe_training_size",
    "probe_within_scale",
    "aggregate_robustness",
]
TABLES = ["controlled", "paired", "sweep", "align_seeds", "variants", "controls", "fusions"]
ROBUSTNESS = ["robustness", "multiplicity", "within_scale", "training_size"]
TARGETS = [
    "results/probes/summary.parquet",
    *[f"results/report/probes/{t}.html" for t in TABLES],
    "results/report/probes/forest",
    "results/report/probes/confusion",
    "results/probes/robustness.parquet",
    *[f"results/report/probes/{t}.html" for t in ROBUSTNESS],
    "results/report/probes/training_size.png",
]
SUMMARY_COLUMNS = {
    "row_id",
    "family",
    "corpus",
    "target",
    "input",
    "t_variant",
    "fusion",
    "align_seed",
    "probe_seed",
    "control",
    "status",
    "metric",
    "v_score",
    "vt_score",
    "delta",
    "ci_low",
    "ci_high",
    "p_gt0",
    "criterion_met",
    "delta_ctrl",
    "controls",
    "v_reg",
    "vt_reg",
    "reg_name",
    "n_train",
    "n_test",
    "converged",
    "notes",
    "null_corpus",
    "design",
    "bootstrap_strata",
    "baseline_score",
    "visible_score",
}


def write_upstream(work: Path, cfg: dict, n: int = 60) -> None:
    """Manifest, splits, feature and aligned edges for every corpus the probe families use."""
    rng = np.random.default_rng(0)
    variants = cfg["preprocess"]["variants"]
    heads = cfg["probes"]["heads"]
    manifest, splits = [], []
    for corpus, spec in sorted(cfg["corpora"].items()):
        ids = [f"{corpus}-{i:05d}" for i in range(n)]
        density = rng.choice([500.0, 2000.0, 5000.0], n)
        scale = np.tile([0.15, 0.2, 0.25], n // 3)
        mass = density * scale**3
        hard = rng.random(n) < 0.5
        force = 2.0 + 3.0 * hard + rng.normal(0, 0.3, n)
        shape = rng.choice(["box", "sphere"], n)
        frame = pd.DataFrame(
            {
                "sample_id": ids,
                "corpus": corpus,
                "sensor_id": "s0",
                "caption": "",
                "stratum": shape,
                "shape": shape,
                "scale": scale,
                "density": density,
                "mass": mass,
                "hardness": np.where(hard, "hard", "soft"),
                "force_p05": force - 0.5,
                "force_p50": force,
                "force_p95": force + 0.5,
            }
        )
        manifest.append(frame)
        if spec.get("design") == "controlled":
            split = np.where(scale == 0.25, "test", np.where(np.arange(n) % 9 == 0, "val", "train"))
        else:
            split = np.array(["train"] * (n - 16) + ["val"] * 4 + ["test"] * 12)
        splits.append(pd.DataFrame({"sample_id": ids, "corpus": corpus, "split": split}))
        # what touch "feels": density, hardness and force -- except on the null corpus
        signal = np.column_stack([np.log(density), hard, force, np.log(mass)])
        if spec.get("null"):
            signal = rng.permutation(signal)
        key = pd.DataFrame({"sample_id": ids})
        base = work / "results/features" / corpus
        vision = {"vit": rng.normal(size=(n, 16)), "pixel": rng.normal(size=(n, 24))}
        edges.write(base / "vision.parquet", key, vision, producer="test")
        for variant in variants:
            t = np.column_stack([signal, rng.normal(size=(n, 12))]) + 0.05 * rng.normal(
                size=(n, 16)
            )
            edges.write(base / f"tactile~{variant}.parquet", key, {"vit": t}, producer="test")
        for fam in cfg["probes"]["families"].values():
            if fam["corpus"] != corpus:
                continue
            for seed in cfg["align"]["seeds"]:
                cell = (
                    f"results/align/{fam['heads_from']}/{heads['variant']}/seed~{seed}/"
                    f"tau~{float(heads['tau'])!r}/n~{heads['n_train']}"
                )
                t_al = np.column_stack([signal, rng.normal(size=(n, 4))])
                vectors = {"v_aligned": rng.normal(size=(n, 8)), "t_aligned": t_al}
                edges.write(
                    work / cell / f"aligned~{corpus}.parquet", key, vectors, producer="test"
                )
    edges.write(
        work / "results/corpus/manifest.parquet",
        pd.concat(manifest, ignore_index=True),
        producer="test",
    )
    edges.write(
        work / "results/corpus/splits.parquet",
        pd.concat(splits, ignore_index=True),
        producer="test",
    )


@pytest.fixture(scope="module")
def cfg() -> dict:
    return merged_config()


@pytest.fixture(scope="module")
def robustness() -> dict:
    """config probes.robustness as the run reads it: validated, the schema's defaults filled."""
    return validated("test.yaml")["probes"]["robustness"]


@pytest.fixture(scope="module")
def probes_run(tmp_path_factory, cfg) -> Path:
    work = copy_tree(tmp_path_factory.mktemp("probes") / "wf")
    write_upstream(work, cfg)
    smk(work, "--cores", "2", *TARGETS, *PROBE_RULES)  # targets must follow a flag
    return work


@pytest.fixture(scope="module")
def full_summary(probes_run) -> pd.DataFrame:
    return tidy(edges.read(probes_run / "results/probes/summary.parquet").frame)


@pytest.fixture(scope="module")
def summary(full_summary) -> pd.DataFrame:
    """The paper's protocol (raw); the variants are tested in test_protocol_variants_*."""
    return full_summary.loc[full_summary["protocol"] == "raw"].reset_index(drop=True)


def test_summary_edge_has_the_documented_columns_and_one_row_per_comparison(summary, cfg):
    assert SUMMARY_COLUMNS <= set(summary.columns), SUMMARY_COLUMNS - set(summary.columns)
    assert summary["row_id"].is_unique
    assert set(summary["family"]) == set(cfg["probes"]["families"])
    ident = ["family", "input", "t_variant", "fusion", "align_seed", "probe_seed", "control"]
    assert not summary[ident].astype(str).duplicated().any()
    assert set(summary["control"]) == {"none", *CONTROLS}
    main = summary.loc[summary["control"] == "none"]
    assert set(main["status"]) <= {"ok", "skipped"}
    # every configured fusion on aligned features, for every alignment seed
    aligned = main.loc[main["input"] == "aligned"]
    assert set(aligned["fusion"]) == set(cfg["probes"]["fusions"])
    assert set(aligned["align_seed"]) == set(cfg["align"]["seeds"])
    # aligned rows only in ViT-V families, and no two families repeat each other's rows
    assert (aligned["vision"] == "vit").all()
    scores = ["v_score", "vt_score", "delta", "ci_low", "ci_high"]
    by_family = {
        fam: tuple(g.sort_values(["fusion", "align_seed"])[scores].round(12).to_numpy().ravel())
        for fam, g in aligned.groupby("family")
    }
    assert len(set(by_family.values())) == len(by_family), "identical aligned rows"
    # the tactile ablation covers every preprocessing variant
    raw_concat = main.loc[(main["input"] == "raw") & (main["fusion"] == "concat")]
    assert set(raw_concat["t_variant"]) == set(cfg["preprocess"]["variants"])
    # pixel-V (24-d) and tactile ViT (16-d) differ: same-dimension fusions are skipped, with why
    skipped = main.loc[main["status"] == "skipped"]
    assert len(skipped) and (skipped["vision"] == "pixel").all()
    assert skipped["notes"].str.contains("needs V and T of equal dimension").all()
    # the criterion is evaluated exactly where the controls ran
    ran = main["controls"] == "run"
    assert main.loc[ran, "criterion_met"].notna().all()
    assert main.loc[~ran, "criterion_met"].isna().all()
    assert (main.loc[ran, "fusion"] == "concat").all()
    hard = main.loc[main["family"] == "hardness"]
    assert set(hard["metric"]) == {"accuracy"} and set(hard["reg_name"]) == {"C"}
    force = main.loc[(main["family"] == "force") & (main["status"] == "ok")]
    assert force["vt_in_band"].between(0, 1).all() and force["band_low_mean"].notna().all()
    ctrl = main.loc[main["design"] == "controlled", "bootstrap_strata"]
    assert ctrl.str.startswith("shape x density x scale").all()
    # every row carries the baselines that size its Delta (constant within a family)
    assert main["baseline_score"].notna().all()
    assert (main.groupby("family")["baseline_score"].nunique() == 1).all()
    assert main.loc[main["design"] == "controlled", "visible_score"].notna().all()


def test_null_corpus_rows_are_present_and_show_no_gain(summary):
    main = summary.loc[(summary["control"] == "none") & (summary["status"] == "ok")]
    null = main.loc[main["null_corpus"].astype(bool)]
    assert set(null["family"]) == {"hardness_null", "force_null"}
    assert not null["criterion_met"].fillna(False).astype(bool).any()
    real = main.loc[(main["family"] == "force") & (main["controls"] == "run")]
    assert (real["ci_low"] > 0).all() and real["criterion_met"].astype(bool).all()


def test_report_items_exist(probes_run):
    report = probes_run / "results/report/probes"
    for name in TABLES:
        html = report_page(report / f"{name}.html")
        assert "<table>" in html and "<tr>" in html, name
    paired = report_page(report / "paired.html")
    assert "hardness" in paired and "null: Δ [95% CI]" in paired
    assert "mass_vit" in report_page(report / "controlled.html")
    # one figure per family: every family with a comparison has a forest plot, every family
    # with a logistic probe its confusion matrices
    summary = edges.read(probes_run / "results/probes/summary.parquet").frame
    forest = sorted(p.stem for p in (report / "forest").glob("*.png"))
    assert forest == sorted(probe_figures.forest_families(summary))
    confusion = sorted(p.stem for p in (report / "confusion").glob("*.png"))
    assert "hardness" in confusion and "force" not in confusion
    for png in [*(report / "forest").glob("*.png"), *(report / "confusion").glob("*.png")]:
        assert png.read_bytes()[:4] == b"\x89PNG", png


def test_probe_edges_are_verified_and_keyed_by_row_id(probes_run, cfg):
    seed = cfg["probes"]["seeds"][0]
    raw = "protocol~raw"
    rows = edges.read(probes_run / f"results/probes/hardness/{raw}/seed~{seed}.parquet")
    assert rows.key == "row_id" and len(rows)
    conf = edges.read(probes_run / f"results/probes/hardness/{raw}/confusion~{seed}.parquet").frame
    assert set(conf["model"]) == {"V", "V+T"} and set(conf["true"]) == {"hard", "soft"}
    empty = edges.read(probes_run / f"results/probes/force/{raw}/confusion~{seed}.parquet")
    assert len(empty) == 0
    log = (probes_run / f"results/logs/probe/hardness/{raw}/seed~{seed}.log").read_text()
    assert "train/val rows" in log and "|none: V " in log


def test_second_run_has_nothing_to_do(probes_run):
    proc = smk(probes_run, "--dry-run", *TARGETS, *PROBE_RULES)  # targets follow a flag
    assert "Nothing to be done" in proc.stdout + proc.stderr


# ------------------------------------------------------------------------ robustness


def test_protocol_variants_run_the_headline_families_with_a_protocol_column(
    full_summary, cfg, robustness
):
    rob = robustness
    main = full_summary.loc[full_summary["control"] == "none"]
    assert set(main["protocol"]) == set(rob["protocols"])
    for protocol in set(rob["protocols"]) - {"raw"}:
        part = main.loc[main["protocol"] == protocol]
        kinds = dict(zip(part["family"], part["kind"], strict=False))
        expected = {
            f
            for f in rob["families"]
            if not (
                protocol == "standardised" and cfg["probes"]["families"][f]["kind"] == "logistic"
            )
        }
        assert set(part["family"]) == expected, (protocol, kinds)
        # the default budget: headline comparisons only, no controls under a variant
        assert (part["fusion"] == "concat").all() and (part["controls"] == "not run").all()
        assert (full_summary.loc[full_summary["protocol"] == protocol, "control"] == "none").all()
    assert full_summary["row_id"].is_unique
    # multiplicity columns: adjusted p at least the raw p, criterion (Holm) implies criterion
    ok = main.loc[main["status"] == "ok"]
    assert (ok["p_holm"] >= ok["p_boot"] - 1e-15).all() and (
        ok["p_bh"] >= ok["p_boot"] - 1e-15
    ).all()
    adj = ok["criterion_adjusted"].fillna(False).astype(bool)
    assert ok.loc[adj, "criterion_met"].astype(bool).all()


def test_robustness_outputs(probes_run, robustness):
    rob = robustness
    long = edges.read(probes_run / "results/probes/robustness.parquet").frame
    assert set(long["protocol"]) == set(rob["protocols"])
    hard_std = long.loc[(long["family"] == "hardness") & (long["protocol"] == "standardised")]
    assert len(hard_std) and hard_std["same_as_raw"].all()
    html = report_page(probes_run / "results/report/probes/robustness.html")
    assert "under every protocol variant" in html and "force" in html
    size = edges.read(probes_run / "results/probes/training_size.parquet").frame
    assert set(size["family"]) == set(rob["training_size"]["families"])
    for (_fam, _seed), g in size.groupby(["family", "subset_seed"]):
        assert g["n_train"].is_monotonic_increasing and (g["n_test"].nunique() == 1)
    splits = edges.read(probes_run / "results/corpus/splits.parquet").frame.set_index("sample_id")
    within = edges.read(probes_run / "results/probes/within_scale.parquet").frame
    assert (
        set(within["protocol"]) == set(rob["protocols"])
        and (within["split"] == "within_scale").all()
    )
    counts = edges.read(probes_run / "results/probes/multiplicity.parquet").frame
    assert {"all", "null corpora"} <= set(counts["family"])
    log = (probes_run / "results/logs/probe_within_scale/mass.log").read_text()
    assert "within-scale split of the train/val rows" in log
    assert (splits.loc[splits.index.str.startswith("sim_controlled"), "split"] == "test").any()
    for name in ROBUSTNESS:
        assert "<table>" in report_page(probes_run / f"results/report/probes/{name}.html"), name
