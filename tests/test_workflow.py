"""Workflow runs on config/test.yaml: the DAG as a user meets it.

One tiny run in a copy of the repository serves most tests (conftest.reference_run); the
session's second run (conftest.resumed_run, killed and resumed in every stage) checks that
every edge is reproduced bit for bit.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from snakemake_run import (
    ROOT,
    SNAKEMAKE,
    copy_run,
    copy_tree,
    edge_hashes,
    merged_config,
    plan_of,
    planned_rules,
    report_page,
    smk,
)

pytestmark = pytest.mark.workflow


@pytest.fixture(scope="module")
def run_dir(reference_run) -> Path:
    """The session's clean run (conftest.reference_run), shared with the fault tests."""
    return reference_run


def test_dry_run_plans_the_whole_dag(cold_dry_run):
    rules = plan_of(cold_dry_run)  # a fresh copy of the repository (conftest)
    for rule in (
        "simulate_corpus",
        "simulate_natural_grid",
        "merge_corpus",
        "fuse_manifest",
        "make_splits",
        "background_subtract",
        "pretrain_backbone",
        "extract_vision_features",
        "extract_tactile_features",
        "share_natural_touch",
        "pretrained_vs_random",
        "train_heads",
        "project_aligned",
        "aggregate_align",
        "probe",
        "aggregate_probes",
        "cost_of_accuracy",
        "edge_manifest",
        "findings",
        "corpus_examples",
        # generate
        "train_generator",
        "sample_generator",
        "fit_generator_baselines",
        "evaluate_generator",
        "aggregate_generate",
        # regime
        "regime_generators",
        "regime_evaluate",
        "regime_look_control",  # config/test.yaml runs two pool sizes: the curve's control
        "visibility_check",
        "aggregate_regime",
        # transfer to a second sensor
        "transfer_evaluate",
        # pixel generators
        "train_pixel_generator",
        "sample_pixel_generator",
        "evaluate_pixel_generators",
        "pixel_curve_point",
        "aggregate_pixel",
    ):
        assert rule in rules, rules
    # 3 corpora, the regime's natural ones at rho 0 and 1, and the transfer corpus
    assert rules["merge_corpus"] == 6


def test_full_run_makes_verified_edges_logs_and_benchmarks(run_dir):
    from tacgen_lib.io import edges, hashed

    manifest = edges.read(run_dir / "results/corpus/manifest.parquet").frame
    splits = edges.read(run_dir / "results/corpus/splits.parquet").frame
    natural = {"sim_natural_r0", "sim_natural_r1"}  # config/test.yaml's regime.rhos
    transfer = {"sim_transfer"}  # config transfer.corpus
    assert (
        set(manifest["corpus"]) == {"sim_paired", "sim_null", "sim_controlled"} | natural | transfer
    )
    assert set(splits["sample_id"]) == set(manifest["sample_id"])
    ctrl = splits.merge(manifest[["sample_id", "scale"]], on="sample_id").query(
        "corpus == 'sim_controlled'"
    )
    assert set(ctrl.loc[ctrl.split == "test", "scale"].round(3)) == {0.25}
    for rule in (
        "simulate_corpus",
        "simulate_natural_grid",
        "merge_corpus",
        "make_splits",
        "edge_manifest",
    ):
        assert (
            list((run_dir / "results/benchmarks" / rule).rglob("*.tsv"))
            or (run_dir / f"results/benchmarks/{rule}.tsv").exists()
        ), rule
        assert list((run_dir / "results/logs").rglob(f"*{rule}*")), rule
    for corpus in ("sim_paired", "sim_null", "sim_controlled"):
        for figure in ("examples", "labels"):
            assert (run_dir / f"results/report/corpus/{corpus}_{figure}.png").stat().st_size > 5000
        # the force bands against the true force, beside the shuffled-force control
        bands = report_page(run_dir / f"results/report/corpus/{corpus}_force_bands.html")
        assert "share of nominal forces inside [p05, p95]" in bands and "(control)" in bands
    table = (run_dir / "results/report/edge_manifest.tsv").read_text()
    assert hashed.sha256_file(run_dir / "results/corpus/splits.parquet") in table


def test_regime_summary_has_every_arm_of_every_cell(run_dir):
    import yaml

    from tacgen_lib.generate.regime import ARMS, SUMMARY_COLUMNS
    from tacgen_lib.generate.regime_sets import regime_corpora
    from tacgen_lib.io import edges

    NATURAL = {"kind": "simulated", "design": "natural"}

    cfg = yaml.safe_load((run_dir / "config/test.yaml").read_text())["regime"]
    summary = edges.read(run_dir / "results/generate/regime/summary.parquet").frame
    assert list(summary.columns) == list(SUMMARY_COLUMNS)
    regime_names = list(regime_corpora({**cfg, "corpus": NATURAL}))
    assert regime_names == ["sim_natural_r0", "sim_natural_r1"]
    cells = {
        (c, n_l, n_p, s, t, a, p)
        for c in regime_names
        for n_l in cfg["n_labelled"]
        for n_p in cfg["n_pool"]
        for s in cfg["seeds"]
        for t in ("hardness", "log_mass")
        for a, p in ARMS
    }
    got = set(
        summary[["corpus", "n_labelled", "n_pool", "seed", "target", "arm", "probe"]].itertuples(
            index=False, name=None
        )
    )
    assert got == cells
    assert summary["score"].notna().all() and (summary["ci_low"] <= summary["ci_high"]).all()
    assert set(summary["rho"]) == {0.0, 1.0}
    # every cell is scored on each labelled draw (the schema's default count)
    assert set(summary["draw"]) == set(range(3))
    # generated touch is sampled for every draw's labelled rows and the test rows (the pool
    # only trains), one sample and the mean of regime.gen_mean_samples
    from tacgen_lib.generate.regime_sets import draw_regime_sets

    splits = edges.read(run_dir / "results/corpus/splits.parquet").frame
    corpus, seed = regime_names[0], cfg["seeds"][0]
    sets = draw_regime_sets(
        splits,
        corpus,
        n_labelled=max(cfg["n_labelled"]),
        n_pool=max(cfg["n_pool"]),
        seed=seed,
    )
    path = (
        run_dir
        / f"results/generate/regime/{corpus}/seed~{seed}/pool~{max(cfg['n_pool'])}/real/t_gen.parquet"
    )
    t_gen = edges.read(path)
    assert set(t_gen.ids) == set(sets.labelled_union(3)) | set(sets.test)
    assert not set(t_gen.ids) & set(sets.pool)
    _, mean = edges.read_vectors(path, "t_gen_mean")
    _, one = edges.read_vectors(path, "t_gen")
    assert mean.shape == one.shape and not (mean == one).all()
    page = run_dir / "results/report/regime"
    for name in ("findings.html", "table.html", "ladder.html", "heatmap.png", "curves.png"):
        assert (page / name).stat().st_size > 500, name
    findings = report_page(page / "findings.html")
    assert "visibility gate on sim_natural_r0" in findings and "Positive control" in findings
    assert "H1 (ρ = 0" in findings
    # two pool sizes: the curve, its verdict and its positive control on the largest rho's
    # corpus (rule regime_look_control: every arm but those needing a generator, a ceiling
    # or distillation, on the look's mean touch plus noise)
    assert "Pool size (hardness, ρ = 1" in findings
    assert "Positive control of the curve (hardness, ρ = 1" in findings
    control = edges.read(run_dir / "results/generate/regime/look_control.parquet").frame
    assert list(control.columns) == list(SUMMARY_COLUMNS)
    assert set(control["corpus"]) == {"sim_natural_r1"}
    assert set(control["n_pool"]) == set(cfg["n_pool"]) and set(control["draw"]) == set(range(3))
    assert not set(control["arm"]) & {"v_tgen", "gen_mean", "v_tgen_shuffled", "distilled"}
    assert {"look_oracle", "knn", "ridge", "kernel_ridge", "v_treal"} <= set(control["arm"])
    assert control["score"].notna().all()
    pool = report_page(page / "pool.html")
    assert "look + noise (control)" in pool
    # the visibility check: every simulated corpus, each factor it shows, both probes
    visibility = edges.read(run_dir / "results/features/visibility.parquet").frame
    # every simulated corpus; of the rho grid, its first corpus (the look -> frame process is
    # the same at every rho)
    assert set(visibility["corpus"]) >= {"sim_paired", "sim_null", regime_names[0]}
    assert not set(visibility["corpus"]) & set(regime_names[1:])
    natural = visibility[visibility["corpus"] == corpus]
    assert set(natural["factor"]) == {"colour", "texture", "shape", "size", "appearance"}
    probes = natural.groupby("factor")["probe"].apply(set).to_dict()
    # the gate's factors (config.yaml's, unless test.yaml sets them): the 2-layer probe's
    gate = yaml.safe_load((run_dir / "config/config.yaml").read_text())["features"]["visibility"]
    test_features = yaml.safe_load((run_dir / "config/test.yaml").read_text())["features"]
    gate = test_features.get("visibility", {}).get("gate", gate["gate"])
    for factor, got in probes.items():
        want = {"linear", "nonlinear"} | ({"mlp2"} if factor in gate else set())
        assert got == want, factor
    # the paired design's appearance_id indexes objects: it is no factor there
    assert "appearance" not in set(visibility.loc[visibility["corpus"] == "sim_paired", "factor"])
    for name in ("table.html", "figure.png"):
        assert (run_dir / "results/report/visibility" / name).stat().st_size > 500, name
    # the natural corpora's scene presses once: their force-band table says there is no band
    bands = report_page(run_dir / "results/report/corpus/sim_natural_r1_force_bands.html")
    assert "no band to check" in bands


def test_language_evidence_reads_every_generator_corpus(run_dir):
    import yaml

    from tacgen_lib.io import edges
    from tacgen_lib.language.adapter import EVIDENCE_COLUMNS, INPUTS

    corpora = yaml.safe_load((run_dir / "config/config.yaml").read_text())["generate"]["corpora"]
    rows = edges.read(run_dir / "results/language/evidence.parquet").frame
    assert list(rows.columns) == list(EVIDENCE_COLUMNS)
    assert set(rows["corpus"]) == set(corpora)
    for _, g in rows.groupby(["corpus", "attribute"]):
        assert sorted(g["input"]) == sorted(INPUTS)
    assert rows["accuracy"].between(0, 1).all()
    page = report_page(run_dir / "results/report/language/table.html")
    assert "generated − shuffled" in page
    findings = report_page(run_dir / "results/report/findings.html")
    assert "Where generated touch helps" in findings  # the regime's rows


def test_backbone_families_page_has_every_family_probe_and_protocol(run_dir):
    import yaml

    from tacgen_lib.io import edges, hashed
    from tacgen_lib.probes.backbone_families import FAMILY_COLUMNS

    cfg = yaml.safe_load((run_dir / "config/test.yaml").read_text())["backbones"]
    protocols = ["raw", "mlp2"]  # the schema's default
    rows = edges.read(run_dir / "results/backbones/summary.parquet").frame
    assert list(rows.columns) == list(FAMILY_COLUMNS)
    want = {f"{f}|{p}|{q}" for f in cfg["run"] for p in cfg["probes"] for q in protocols}
    assert set(rows["row_id"]) == want and (rows["status"] == "ok").all()
    assert rows["null_corpus"].any() and not rows["null_corpus"].all()  # the control beside
    # the main family's rows are the probe jobs' headline rows, not computed again
    main = rows[rows["family"] == "simclr"]
    assert (main["notes"] == "the probes stage's headline row (rule probe)").all()
    probe = edges.read(run_dir / "results/probes/hardness/protocol~raw/seed~42.parquet").frame
    head = probe[
        (probe["input"] == "raw") & (probe["fusion"] == "concat") & (probe["control"] == "none")
    ]
    assert main.set_index("row_id").loc["simclr|hardness|raw", "delta"] == head["delta"].item()
    # every other family made its own backbones, labelled as made
    for family in ("dinov2", "resnet", "mae"):
        for modality in ("vision", "tactile"):
            hashed.verify(run_dir / f"results/features/families/{family}/{modality}.pt")
    labels = dict(zip(rows["family"], rows["vision_backbone"], strict=False))
    assert labels["resnet"] == "resnet_tiny (random init)" and labels["mae"] == "vit_tiny (MAE)"
    page = report_page(run_dir / "results/report/backbones/table.html")
    for needle in ("2-layer MLP", "null", "resnet (V resnet_tiny (random init)"):
        assert needle in page, needle
    findings = report_page(run_dir / "results/report/findings.html")
    assert "another encoder family? (resnet" in findings and "null corpus V+T − V" in findings


def test_transfer_page_has_every_heads_view_and_probe_seed_and_objects_stay_in_one_split(
    run_dir,
):
    import yaml

    from tacgen_lib.io import edges
    from tacgen_lib.probes.transfer import HEADS_VIEWS, TRANSFER_COLUMNS

    cfg = yaml.safe_load((run_dir / "config/test.yaml").read_text())
    seeds = [str(s) for s in cfg["transfer"]["probe_seeds"]]
    rows = edges.read(run_dir / "results/transfer/summary.parquet").frame
    assert list(rows.columns) == list(TRANSFER_COLUMNS)
    heads_seeds = [str(s) for s in cfg["align"]["seeds"]]  # every alignment seed's heads
    assert set(rows["row_id"]) == {f"none|-|{s}" for s in [*seeds, "mean"]} | {
        f"{v}|{h}|{s}" for v in HEADS_VIEWS[1:] for h in heads_seeds for s in [*seeds, "mean"]
    }
    views = rows.drop_duplicates("heads").set_index("heads")["heads_from"].to_dict()
    assert views == {
        "none": "",
        "source": "sim_paired",
        "target": "sim_transfer",
        "floor": "sim_null",
    }
    assert rows[["ba_v", "ba_vt", "ba_vt_shuffled"]].stack().between(0, 1).all()
    # the transfer corpus's contacts: every object in one split, the test objects new
    manifest = edges.read(run_dir / "results/corpus/manifest.parquet").frame
    splits = edges.read(run_dir / "results/corpus/splits.parquet").frame
    t = manifest[manifest["corpus"] == "sim_transfer"].merge(splits, on=["sample_id", "corpus"])
    assert len(t) == cfg["corpora"]["sim_transfer"]["n"]
    assert (t.groupby("appearance_id")["split"].nunique() == 1).all()
    assert (t.groupby("appearance_id").size() == cfg["corpora"]["sim_transfer"]["contacts"]).all()
    page = report_page(run_dir / "results/report/transfer/table.html")
    assert "shuffled" in page and "retrained (upper)" in page
    findings = report_page(run_dir / "results/report/findings.html")
    assert "transfer to a second sensor" in findings


def test_pixel_page_judges_every_arm_on_both_axes_and_the_curve_has_every_point(run_dir):
    import pandas as pd
    import yaml

    from tacgen_lib.generate.pixel.curve import CURVE_COLUMNS
    from tacgen_lib.generate.pixel.utility import ddpm_arm
    from tacgen_lib.io import edges

    cfg = yaml.safe_load((run_dir / "config/test.yaml").read_text())["pixel"]
    cells = cfg["ddpm_cells"]
    arms = ["pix2pix"] + [ddpm_arm(w, s) for w in cells["guidance"] for s in cells["steps"]]
    judged = {a for arm in arms for a in (arm, f"{arm}_cal")}
    summary = pd.read_parquet(run_dir / "results/pixel/summary.parquet")
    assert judged | {"real_lowres", "t_real", "t_ridge", "latent"} == set(summary["arm"])
    gen = summary[summary["arm"].isin(judged)]
    # both axes on every arm: reconstruction with its interval, utility with its CI and control
    for col in ("pixel_l2", "ssim", "std_ratio", "highpass_ratio", "delta", "ci_low", "ci_high"):
        assert gen[col].notna().all(), col
    assert gen["shuffled_delta"].notna().all() and (gen["ssim"] <= 1).all()
    assert (gen["pixel_l2_low"] <= gen["pixel_l2"]).all()
    # the frames the ViT read: uint8 PNGs at pixel.size, for every row of the corpus
    frames = edges.read(run_dir / "results/pixel/sim_paired/arms/pix2pix/seed~0/frames.parquet")
    assert len(frames) == 24 and frames.vectors["vit"].shape == frames.vectors["vit_cal"].shape
    points = pd.concat(
        edges.read(p).frame for p in (run_dir / "results/pixel/curve").rglob("p~*.parquet")
    )
    assert list(points.columns) == list(CURVE_COLUMNS)
    fractions = sorted(float(p) for p in cfg["curve"]["fractions"])
    assert sorted(set(points["fraction"])) == fractions
    # p = 0 once (both pairings share the real-only heads); every p > 0 both pairings
    assert set(points.loc[points["fraction"] > 0, "pairing"]) == {"generated", "shuffled"}
    assert set(points.loc[points["fraction"] == 0, "pairing"]) == {"generated"}
    page = report_page(run_dir / "results/report/pixel/architecture.html")
    assert "Pix2Pix" in page and "shuffled" in page and "LPIPS" in page
    findings = report_page(run_dir / "results/report/findings.html")
    assert "pixel generators" in findings


def test_second_run_has_nothing_to_do(run_dir):
    assert planned_rules(run_dir) == {}


def test_changed_param_reruns_only_its_downstream(run_dir, tmp_path):
    work = copy_run(run_dir, tmp_path / "b")
    assert planned_rules(work) == {}
    cfg = work / "config/test.yaml"
    cfg.write_text(cfg.read_text().replace("examples_per_corpus: 3", "examples_per_corpus: 2"))
    assert set(planned_rules(work)) == {"corpus_examples", "all"}


def test_changed_probe_param_reruns_only_the_probes(run_dir, tmp_path):
    work = copy_run(run_dir, tmp_path / "p")
    cfg = work / "config/test.yaml"
    cfg.write_text(
        cfg.read_text().replace("probes:\n  bootstrap: 200", "probes:\n  bootstrap: 150")
    )
    assert "probes:\n  bootstrap: 150" in cfg.read_text()
    # the robustness rules read the same probes subtree, and the generator's
    # evaluation and its baselines use the probes' settings (same probe code): all downstream
    robustness = {"probe_training_size", "probe_within_scale", "aggregate_robustness"}
    generate = {"fit_generator_baselines", "evaluate_generator", "aggregate_generate"}
    # the cost page's free generator knobs read the generation summary; the
    # findings page reads the probe summary
    cost = {"cost_knob_points", "cost_of_accuracy"}
    report = {"findings", "edge_manifest", "all"}
    # the regime's probes read the probes subtree (their grids and folds) and the language
    # evidence its bootstrap count
    regime = {
        "regime_evaluate",
        "regime_look_control",
        "visibility_check",
        "aggregate_regime",
        "language_evidence",
        "aggregate_language",
    }
    # the backbone families' probes use the probes' settings, and the main family's rows are
    # the probe jobs' own
    backbones = {"family_probe", "aggregate_backbones"}
    # the pixel generators' utility and scale curve are judged by the same probes (their
    # training and sampling are not)
    pixel = {"evaluate_pixel_generators", "pixel_curve_point", "aggregate_pixel"}
    assert set(planned_rules(work)) == {"probe", "aggregate_probes"} | (
        robustness | generate | cost | report | regime | backbones | pixel
    )


def test_changed_library_module_reruns_only_its_users(run_dir, tmp_path):
    work = copy_run(run_dir, tmp_path / "c")
    module = work / "tacgen_lib/features/pretrained_vs_random.py"
    module.write_text(module.read_text() + "\n# an edit that changes the module's content\n")
    # the cost page reads knob points only, not the pretrained-vs-random edge
    assert set(planned_rules(work)) == {
        "pretrained_vs_random",
        "edge_manifest",
        "all",
    }


def test_edit_to_an_indirectly_imported_module_reruns_exactly_its_users(run_dir, tmp_path):
    """controls.py is imported by no script, only through probes.compare."""
    from tacgen_lib.io.imports import import_closure

    module = "tacgen_lib/probes/controls.py"
    scripts = ROOT / "workflow/scripts"
    imports = re.compile(
        r"tacgen_lib\.probes\.controls\b|from tacgen_lib\.probes import .*\bcontrols\b"
    )
    direct = [p.name for p in scripts.glob("*.py") if imports.search(p.read_text())]
    users = {
        p.stem
        for p in scripts.glob("*.py")
        if ROOT / module in import_closure(p, ROOT / "tacgen_lib")
    }
    # the generator's evaluation and baselines fit probes (probes.fit, probes.rows) but run no
    # control, so they do not reach it since the protocol was split by concept
    robustness = {"probe_training_size", "probe_within_scale", "aggregate_robustness"}
    # the backbone families compare V with V+T through probes.compare as well
    backbones = {"family_probe", "aggregate_backbones"}
    assert direct == []
    assert users == {"probe", "aggregate_probes"} | robustness | backbones
    work = copy_run(run_dir, tmp_path / "f")
    (work / module).write_text((work / module).read_text() + "\n# an edit\n")
    # its users rerun, then only what reads their outputs: the findings page, the edge
    # manifest, `all` and the backbone-family knob's points with the cost page (the free knobs
    # run in every config; the swept ones only under config/cost.yaml: not planned here)
    assert set(planned_rules(work)) == users | {
        "edge_manifest",
        "findings",
        "all",
        "cost_knob_points",
        "cost_of_accuracy",
    }


def test_two_runs_give_identical_edges(run_dir, resumed_run):
    """Determinism: every edge of a second run in another directory (the session's kill series,
    conftest.resumed_run: cold, killed in every stage, resumed to the end, so each of its edges
    was computed there again) equals the clean run's bit for bit. The same computation twice:
    same code, config, seeds and thread counts on one machine."""
    assert resumed_run["final"]["exit"] == 0, resumed_run["final"]["log"][-6000:]
    first, second = edge_hashes(run_dir), edge_hashes(resumed_run["work"])
    assert first and first == second


def test_report_builds_offline_and_reads_in_a_browser(run_dir):
    """The report as a reader meets it: opened in headless Chromium (Debian's chromium and
    chromium-driver, driven by Selenium) at 1600 × 1000, every category and every result
    clicked. Fails if the findings page is not first, a result shows nothing, a figure is
    cropped or shown smaller than its pixels, a table is wider than its frame or breaks a word
    across lines, or a caption is missing (tools/browse_report.py says which and why)."""
    built = smk(run_dir, "--report", "results/report.html")
    # nothing a user cannot act on: no warning from Snakemake's resource evaluation
    assert "RuntimeWarning" not in built.stdout + built.stderr, built.stderr[-3000:]
    html = (run_dir / "results/report.html").read_text(errors="replace")
    assert len(html) > 10_000
    for needle in ("edge_manifest", "sim_paired_examples", "01 Findings"):
        assert needle in html, needle
    sys.path.insert(0, str(ROOT / "tools"))
    from browse_report import browse

    from tacgen_lib.report_pages import PAGES, page_of

    menu, visits, problems = browse(run_dir / "results/report.html")
    assert [page_of(c) for c in menu] == [p for p in PAGES if p in map(page_of, menu)]
    assert menu[0] == "01 Findings" and not problems, problems
    bad = [f"{v.category} / {v.subcategory} / {v.name}: {v.problems}" for v in visits if v.problems]
    assert not bad, "\n".join(bad)
    # every result of the report was visited, figures and tables alike
    assert {v.kind for v in visits} == {"img", "html"} and len(visits) >= 30


def test_tampered_edge_is_refused(run_dir, tmp_path):
    work = copy_run(run_dir, tmp_path / "t")
    target = work / "results/corpus/manifest.parquet"
    data = bytearray(target.read_bytes())
    data[100] ^= 0xFF
    target.write_bytes(bytes(data))
    proc = smk(work, "--forcerun", "make_splits", check=False)
    assert proc.returncode != 0
    log = (work / "results/logs/make_splits.log").read_text()
    assert "manifest.parquet: SHA-256" in log and "does not match the manifest" in log
    assert target.read_bytes() == bytes(data)


def refused_dry_run(work: Path, old: str, new: str) -> str:
    """The output of a dry run of `work` with `old` replaced by `new` in config/test.yaml,
    which must fail."""
    cfg = work / "config/test.yaml"
    cfg.write_text(cfg.read_text().replace(old, new))
    proc = smk(work, "--dry-run", check=False)
    assert proc.returncode != 0
    return proc.stdout + proc.stderr


def test_bad_config_stops_with_the_key_named(tmp_path):
    out = refused_dry_run(copy_tree(tmp_path / "bad"), "taus: [0.07]", "taus: [-0.07]")
    assert "align.taus[0]: -0.07 is less than or equal to the minimum of 0" in out


def test_a_regime_that_cannot_be_drawn_stops_before_any_job_naming_the_sizes(tmp_path):
    work = copy_tree(tmp_path / "regime")
    out = refused_dry_run(work, "  n_pool: [12, 24]", "  n_pool: [12, 48]")
    assert "corpus 'sim_natural_r0' has 48 non-test rows (60 rows, 12 test)" in out
    assert "(16) and the largest pool (48) need 64 disjoint rows" in out
    assert not (work / "results").exists()


def test_real_corpus_path_runs_on_fixtures(tmp_path):
    """The TVL ingest path end to end: SSVTP and HCT fixtures in the real layouts."""
    sys.path.insert(0, str(ROOT / "tests"))
    from fixtures_real import write_hct_fixture, write_ssvtp_fixture

    from tacgen_lib.io import edges

    data = tmp_path / "tvl"
    write_ssvtp_fixture(data, n=12)
    write_hct_fixture(data, n_traj=2, per_traj=4)
    work = copy_tree(tmp_path / "real")
    from snakemake.utils import update_config

    cfg = yaml.safe_load((work / "config/config.yaml").read_text())
    update_config(cfg, yaml.safe_load((work / "config/test.yaml").read_text()))
    cfg["run_name"] = "real-fixture"
    cfg["corpora"] = {
        "ssvtp": {"kind": "ssvtp", "root": str(data)},
        "hct": {"kind": "hct", "root": str(data)},
    }
    cfg["splits"].pop("by_scale")
    cfg["splits"].pop("by_object")  # the transfer corpus is simulated: no transfer stage here
    cfg["transfer"]["corpus"] = None
    cfg["features"]["pretrain"]["corpus"] = "ssvtp"
    cfg["features"]["pretrained_vs_random"]["corpus"] = "ssvtp"
    cfg["align"]["corpora"] = ["ssvtp"]
    cfg["generate"]["corpora"] = {"ssvtp": {"hardness": "logistic"}}  # generate
    cfg["regime"]["rhos"] = []  # the regime needs simulated natural corpora
    # the pixel generators judge and retrain heads on the real corpus
    cfg["pixel"]["corpora"] = {"ssvtp": {"hardness": "logistic"}}
    cfg["pixel"]["curve"]["corpora"] = {"ssvtp": {"hardness": "logistic"}}
    # the official-checkpoint path: a ViT-S/14 state dict in DINOv2's key format (random
    # weights, 518-px position grid as released), loaded and interpolated instead of pretraining
    import torch

    from tacgen_lib.features.vit import build_vit

    ckpt = tmp_path / "dinov2_vits14_pretrain.pth"
    torch.manual_seed(0)
    torch.save(build_vit("vit_small", img_size=518).state_dict(), ckpt)
    cfg["features"]["backbones"]["vision"] = {"arch": "vit_small", "checkpoint": str(ckpt)}
    cfg["probes"]["families"] = {
        "hardness": {
            "corpus": "ssvtp",
            "heads_from": "ssvtp",
            "target": "hardness",
            "kind": "logistic",
            "vision": "vit",
        }
    }
    # the robustness runs name families too: a config that replaces the families says which
    rob = cfg["probes"]["robustness"]
    rob["families"] = rob["training_size"]["families"] = ["hardness"]
    rob["within_scale"]["families"] = []  # no appearance-controlled corpus here
    cfg["backbones"]["probes"] = ["hardness"]  # and so do the backbone families
    (work / "config/real.yaml").write_text(yaml.safe_dump(cfg))
    targets = [
        "results/features/ssvtp/vision.parquet",
        "results/features/hct/tactile~clip128.parquet",
        "results/report/corpus/ssvtp_examples.png",
        "results/report/corpus/hct_examples.png",
    ]
    proc = subprocess.run(
        [
            *SNAKEMAKE,
            "--cores",
            "2",
            "--configfile",
            "config/real.yaml",
            "--replace-workflow-config",
            *targets,
        ],
        cwd=work,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-6000:]
    manifest = edges.read(work / "results/corpus/manifest.parquet").frame
    assert manifest["corpus"].value_counts().to_dict() == {"ssvtp": 12, "hct": 8}
    assert (work / "results/report/corpus/ssvtp_examples.png").stat().st_size > 1000
    for corpus in ("ssvtp", "hct"):  # real corpora record no contact force, and say so
        bands = report_page(work / f"results/report/corpus/{corpus}_force_bands.html")
        assert "no true contact force recorded" in bands
    assert len(edges.read(work / "results/features/hct/tactile~clip128.parquet")) == 8
    vision = edges.read(work / "results/features/ssvtp/vision.parquet", require={"vit": 384})
    assert len(vision) == 12  # ViT-S/14 features from the checkpoint


def test_runs_as_a_module_from_another_directory(tmp_path, cold_dry_run):
    """Deployed as catalogue workflows are (what `snakedeploy deploy-workflow` writes): a
    directory holding a `Snakefile` whose `module` block points at this repository, and the
    user's `config/` (a full config and the scenes it names). The files the workflow reads
    from its own tree (schema, scripts, library) resolve against its source: the whole DAG is
    planned there, and one corpus is simulated and merged there (the user's scenes, the
    workflow's scripts)."""
    repo = copy_tree(tmp_path / "repo")
    user = tmp_path / "user"
    (user / "config").mkdir(parents=True)
    cfg = merged_config()
    cfg["run_name"] = "deployed"
    (user / "config" / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    shutil.copy2(repo / "config" / "scenes.yaml", user / "config" / "scenes.yaml")
    (user / "Snakefile").write_text(
        'configfile: "config/config.yaml"\n\n'
        "module tacgen:\n"
        f"    snakefile:\n        {str(repo / 'Snakefile')!r}\n"
        "    config:\n        config\n\n"
        "use rule * from tacgen\n"
    )
    cmd = [*SNAKEMAKE, "--cores", "2"]
    dry = subprocess.run([*cmd, "--dry-run"], cwd=user, capture_output=True, text=True, timeout=300)
    assert dry.returncode == 0, dry.stderr[-4000:]
    planned = plan_of(dry)
    assert planned == plan_of(cold_dry_run), planned  # a plain dry run of test.yaml
    run = subprocess.run(
        [*cmd, "results/corpus/sim_paired/samples.parquet"],
        cwd=user,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-4000:]

    from tacgen_lib.io import hashed

    hashed.verify(user / "results/corpus/sim_paired/samples.parquet")
    assert not (repo / "results").exists()  # everything lands in the user's directory


def test_policy_cost_table_and_cost_page_give_one_run_the_same_seconds(run_dir):
    """A policy setting's seconds on the cost page (training job + rollout shards) and the
    total the Policy page's cost table gives its cell are one number, not two."""
    import html as html_lib
    import re

    import pandas as pd

    points = pd.read_parquet(run_dir / "results/cost/points/policy_width.parquet")
    page = report_page(run_dir / "results/report/policy/cost.html")
    rows = re.findall(r"<tr>(.*?)</tr>", page)
    heads = [html_lib.unescape(h) for h in re.findall(r"<th>(.*?)</th>", rows[0])]
    table = {}
    for row in rows[1:]:
        cells = [html_lib.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", row)]
        table[cells[0]] = dict(zip(heads, cells, strict=True))
    for p in points.itertuples():
        cells = [c for c in table if c.startswith(f"v/H~{int(p.setting)}/")]
        assert cells, (p.label, list(table))
        totals = [float(table[c]["total s"]) for c in cells]
        assert np.mean(totals) == pytest.approx(p.wall_s, abs=0.01), (p.label, totals)


def test_the_browser_check_names_wide_tables_and_broken_words():
    sys.path.insert(0, str(ROOT / "tools"))
    from browse_report import check_frame

    fits = {"empty": False, "scroll": [1000, 1000], "broken": []}
    assert check_frame(fits) == []
    wide = {**fits, "scroll": [1300, 1200], "broken": ["hardness"]}
    assert check_frame(wide) == [
        "wider than its frame: 1300 px in 1200 px",
        "words broken across lines: ['hardness']",
    ]
    assert check_frame({"empty": True}) == ["shows nothing: empty HTML page"]
