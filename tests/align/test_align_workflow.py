"""The alignment stage in the workflow (rules train_heads, project_aligned, aggregate_align).

The workflow run uses config/test.yaml with synthetic upstream edges (split edge and feature
edges written with `tacgen_lib.io.edges`, only the align rules allowed), so it takes seconds; the
full DAG including the real features is run by tests/test_workflow.py. Unit tests cover the
library path the rule scripts call (split guard, cell ids, summary and tables).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from snakemake_run import copy_tree, report_page, smk

from tacgen_lib.align import checkpoint as align_checkpoint
from tacgen_lib.align import grid as align_grid  # noqa: E402
from tacgen_lib.align.cell_names import cell_name
from tacgen_lib.align.settings import AlignSettings  # noqa: E402
from tacgen_lib.corpus.splits import LeakageError  # noqa: E402
from tacgen_lib.io import edges  # noqa: E402
from tacgen_lib.report import align as align_report  # noqa: E402

CELL = "seed~42/tau~0.07/n~all"
ALIGN_RULES = ["--allowed-rules", "train_heads", "project_aligned", "aggregate_align"]
TARGETS = [
    "results/align/summary.parquet",
    "results/report/align/seeds.html",
    f"results/align/sim_paired/clip128/{CELL}/aligned~sim_controlled.parquet",
]


def synthetic_corpus(corpus: str, n: int, paired: bool, seed: int, dim: int = 24):
    """Feature edges' content: T a noisy linear map of V (paired) or independent of it (null)."""
    rng = np.random.default_rng(seed)
    ids = [f"{corpus}-{i:06d}" for i in range(n)]
    v = rng.normal(size=(n, dim)).astype(np.float32)
    mix = rng.normal(size=(dim, dim)) / np.sqrt(dim)
    t = (v @ mix if paired else rng.normal(size=(n, dim))) + 0.1 * rng.normal(size=(n, dim))
    pix_v, pix_t = rng.random((n, 12)), rng.random((n, 12))
    split = np.array(["train"] * (n - 12) + ["val"] * 4 + ["test"] * 8, dtype=object)
    return ids, v, t.astype(np.float32), pix_v, pix_t, split


def write_upstream(work: Path) -> None:
    """splits.parquet and every feature edge the align rules read, for three corpora."""
    rows = []
    for k, (corpus, paired) in enumerate(
        [("sim_paired", True), ("sim_null", False), ("sim_controlled", True)]
    ):
        ids, v, t, pv, pt, split = synthetic_corpus(corpus, 40, paired, seed=k)
        key = pd.DataFrame({"sample_id": ids})
        base = work / "results/features" / corpus
        edges.write(base / "vision.parquet", key, {"vit": v, "pixel": pv}, producer="test")
        edges.write(base / "tactile~clip128.parquet", key, {"vit": t, "pixel": pt}, producer="test")
        rows.append(pd.DataFrame({"sample_id": ids, "corpus": corpus, "split": split}))
    splits = pd.concat(rows, ignore_index=True).sort_values("sample_id", ignore_index=True)
    edges.write(work / "results/corpus/splits.parquet", splits, producer="test")


@pytest.fixture(scope="module")
def align_run(tmp_path_factory) -> Path:
    work = copy_tree(tmp_path_factory.mktemp("align") / "wf")
    write_upstream(work)
    smk(work, "--cores", "2", *TARGETS, "--set-threads", "train_heads=1", *ALIGN_RULES)
    return work


def test_summary_has_one_row_per_cell_with_the_documented_columns(align_run):
    summary = pd.read_parquet(align_run / "results/align/summary.parquet")
    assert tuple(summary.columns) == align_report.SUMMARY_COLUMNS
    assert list(summary["cell"]) == [f"sim_null/clip128/{CELL}", f"sim_paired/clip128/{CELL}"]
    assert set(summary["corpus"]) == {"sim_paired", "sim_null"}
    assert (summary["train_seconds"] > 0).all()  # from the benchmark files
    assert np.allclose(summary["chance_top1"], 1 / 8) and np.allclose(summary["chance_top5"], 5 / 8)
    for col in ("top1_v2t", "top1_t2v", "top5_v2t", "top5_t2v"):
        assert summary[col].between(0, 1).all(), col
    assert (summary["top5_v2t"] >= summary["top1_v2t"]).all()
    assert summary["median_rank_v2t"].between(1, 8).all()
    # the hashed per-cell metrics agree with the summary (which adds only the wall time)
    cells = edges.read(align_run / "results/align/metrics.parquet").frame
    merged = summary.merge(cells, on="cell", suffixes=("", "_edge"))
    assert np.array_equal(merged["top1_v2t"], merged["top1_v2t_edge"])
    assert "train_seconds" not in cells.columns
    assert set(cells["n_test"]) == {8} and set(cells["n_train_rows"]) == {28}


def test_cell_outputs_are_verified_edges(align_run):
    folder = align_run / "results/align/sim_paired/clip128" / CELL
    heads = align_checkpoint.load_heads(folder / "heads.pt")  # verifies the sidecar hash
    assert heads.meta["config"]["tau"] == 0.07 and heads.meta["config"]["n_train"] == 28
    curve = edges.read(folder / "curve.parquet").frame
    assert curve["step"].iloc[0] == 0 and curve["step"].is_monotonic_increasing
    aligned = edges.read(folder / "aligned~sim_controlled.parquet", require={"v_aligned": 128})
    assert len(aligned) == 40 and set(aligned.frame["corpus"]) == {"sim_controlled"}
    np.testing.assert_allclose(np.linalg.norm(aligned.vectors["t_aligned"], axis=1), 1, rtol=1e-5)
    log = align_run / "results/logs/train_heads/sim_paired/clip128/seed~42/tau~0.07/n~all.log"
    text = log.read_text()
    assert "align step 0/" in text and "28 train / 4 val / 8 test rows" in text


def test_report_items_exist(align_run):
    report = align_run / "results/report/align"
    for name in ("tau_ablation.html", "n_scaling.html", "seeds.html"):
        html = report_page(report / name)
        assert "<table>" in html and "sim_paired" in html and "sim_null" in html, name
    assert "τ ablation" in report_page(report / "tau_ablation.html")
    assert (report / "curves.png").read_bytes()[:4] == b"\x89PNG"


def test_second_run_has_nothing_to_do(align_run):
    proc = smk(align_run, "--dry-run", *TARGETS, *ALIGN_RULES)  # targets follow a flag
    assert "Nothing to be done" in proc.stdout + proc.stderr


# ---------------------------------------------------------------------------------------------
# The library path of the rule scripts
# ---------------------------------------------------------------------------------------------


def _edges_in_memory(n: int = 40):
    ids, v, t, _, _, split = synthetic_corpus("c", n, True, seed=3)
    key = pd.DataFrame({"sample_id": ids})
    vision = edges.Edge(path=Path("vision.parquet"), frame=key, vectors={"vit": v})
    tactile = edges.Edge(path=Path("tactile.parquet"), frame=key.copy(), vectors={"vit": t})
    splits = pd.DataFrame({"sample_id": ids, "corpus": "c", "split": split})
    return vision, tactile, splits


TRAIN = AlignSettings.tiny(steps=4, batch_size=8, weight_decay=0.0, eval_every=2)


def test_split_guard_refuses_a_poisoned_split():
    vision, tactile, splits = _edges_in_memory()
    ids = align_grid.cell_ids(splits, corpus="c", n_train="all", seed=0)
    test_id = ids["test"][0]
    poisoned = {**ids, "train": np.append(ids["train"], test_id)}
    with pytest.raises(LeakageError, match=f"train_heads.*{test_id}.*'test'"):
        align_grid.fit_cell(
            vision, tactile, splits, poisoned, tau=0.1, seed=0, settings=TRAIN, device="cpu"
        )
    # validation rows only steer early stopping: a train row among them is refused too
    val_poisoned = {**ids, "val": np.append(ids["val"], ids["train"][0])}
    with pytest.raises(LeakageError, match=str(ids["train"][0])):
        align_grid.fit_cell(
            vision, tactile, splits, val_poisoned, tau=0.1, seed=0, settings=TRAIN, device="cpu"
        )
    # and a split edge that calls a test row "train" is caught by the train/test overlap check
    relabelled = splits.copy()
    relabelled.loc[relabelled["sample_id"] == test_id, "split"] = "train"
    with pytest.raises(ValueError, match=f"{test_id}.*both a test row and a training row"):
        align_grid.fit_cell(
            vision, tactile, relabelled, poisoned, tau=0.1, seed=0, settings=TRAIN, device="cpu"
        )


def test_fit_cell_evaluates_on_test_rows_only():
    vision, tactile, splits = _edges_in_memory()
    ids = align_grid.cell_ids(splits, corpus="c", n_train=16, seed=1)
    fit = align_grid.fit_cell(
        vision, tactile, splits, ids, tau=0.1, seed=1, settings=TRAIN, device="cpu"
    )
    assert fit.metrics["n_test"] == 8 and fit.metrics["n_train_rows"] == 16
    assert fit.metrics["chance_top1"] == 1 / 8 and fit.metrics["steps_run"] == 4
    assert list(fit.curve["eval"]) == ["step~0", "step~2", "step~4"]
    with pytest.raises(edges.EdgeError, match="no vector column 'pixel'"):
        align_grid.fit_cell(
            vision,
            tactile,
            splits,
            ids,
            tau=0.1,
            seed=1,
            settings=replace(TRAIN, feature="pixel"),
            device="cpu",
        )


def test_train_subset_is_seeded_nested_and_bounded():
    ids = [f"s{i:03d}" for i in range(50)]
    a, b = align_grid.train_subset(ids, 10, seed=5), align_grid.train_subset(ids[::-1], 10, seed=5)
    assert list(a) == list(b) and len(set(a)) == 10  # depends on the id set, not its order
    assert set(a) <= set(align_grid.train_subset(ids, 20, seed=5))  # nested across N
    assert list(a) != list(align_grid.train_subset(ids, 10, seed=6))
    assert len(align_grid.train_subset(ids, "all", seed=0)) == 50
    with pytest.raises(ValueError, match="n_train=60 but the train split has only 50 rows"):
        align_grid.train_subset(ids, 60, seed=0)
    for bad in ("ALL", "1", "07", 1.5):
        with pytest.raises(ValueError, match="n_train must be"):
            align_grid.parse_n_train(bad)


def test_tables_report_mean_and_sd_over_seeds():
    rows = []
    for seed, top1 in ((1, 0.5), (2, 0.7)):
        for n in ("10", "all"):
            cell = cell_name("p", "clip128", seed, "0.07", n)
            rows.append(
                {
                    "cell": cell,
                    "corpus": "p",
                    "variant": "clip128",
                    "seed": seed,
                    "tau": "0.07",
                    "n_train": n,
                    "budget": "steps",
                    "val_loss": 1.0,
                    "top1_v2t": top1,
                    "top1_t2v": top1,
                    "top5_v2t": 1.0,
                    "top5_t2v": 1.0,
                    "median_rank_v2t": 1.0,
                    "median_rank_t2v": 2.0,
                    "chance_top1": 0.1,
                    "chance_top5": 0.5,
                }
            )
    metrics = pd.DataFrame(rows)
    seconds = {c: 2.0 for c in metrics["cell"]}
    summary = align_report.alignment_summary(metrics, seconds)
    assert tuple(summary.columns) == align_report.SUMMARY_COLUMNS
    table = align_report.n_scaling_table(summary, "0.07")
    assert list(table["n_train"]) == ["10", "all"]  # numeric N first, then all
    assert table["top1_v2t"].iloc[0] == f"0.600 ± {np.std([0.5, 0.7], ddof=1):.3f}"
    assert align_report.tau_ablation_table(summary, "all")["seeds"].tolist() == [2]
    with pytest.raises(ValueError, match="has metrics but no benchmark time"):
        align_report.alignment_summary(metrics, {**seconds, "x/y/seed~1/tau~0.1/n~all": 1.0})
