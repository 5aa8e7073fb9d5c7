"""Cost of accuracy (DESIGN §7): every knob's accuracy against its run time.

Run times come from the Snakemake `benchmark:` file of the job that produced a metric (wall
seconds, column `s`), never from inside an edge (edges must be reproducible bit for bit).
Each row is one job: which knob it varies, its setting, the seconds it took and the metric it
produced, so a reader sees what an extra epoch, sample or resample buys.
"""

from __future__ import annotations

from collections.abc import Mapping

import matplotlib.pyplot as plt
import pandas as pd

__all__ = ["COST_COLUMNS", "cost_rows", "cost_figure"]

COST_COLUMNS = ["stage", "knob", "setting", "seconds", "metric", "value"]


def cost_rows(
    *,
    align_summary: pd.DataFrame,
    pretrain: pd.DataFrame,
    pretrain_seconds: Mapping[str, float],
    simulate_seconds: Mapping[str, float],
    corpus_sizes: Mapping[str, int],
    probe_seconds: Mapping[str, float] | None = None,
    probe_summary: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """Tidy cost-of-accuracy table.

    align_summary: results/align/summary.parquet (train_seconds, top1_v2t per cell);
    pretrain: results/features/pretrained_vs_random.parquet; pretrain_seconds: modality -> s;
    simulate_seconds: corpus -> total simulation seconds over its shards; corpus_sizes: corpus
    -> samples; probe_seconds: family -> s of its probe jobs, with probe_summary giving the
    family's main Δ and CI width.
    """
    rows = []
    for r in align_summary.itertuples(index=False):
        setting = f"{r.corpus} {r.variant} seed {r.seed} τ {r.tau} N {r.n_train} ({r.budget})"
        rows.append(
            ("align", "alignment cell", setting, r.train_seconds, "top-1 V→T (test)", r.top1_v2t)
        )
    for r in pretrain.itertuples(index=False):
        secs = pretrain_seconds.get(r.modality)
        rows.append(
            (
                "features",
                f"{r.modality} backbone pretraining",
                f"{r.arch}",
                secs,
                f"Δ accuracy vs random ({r.target})",
                r.delta,
            )
        )
    for corpus, secs in simulate_seconds.items():
        n = corpus_sizes.get(corpus, 0)
        rows.append(
            (
                "corpus",
                "corpus size",
                f"{corpus}: {n} samples",
                secs,
                "ms per sample",
                1000 * secs / max(n, 1),
            )
        )
    if probe_seconds and probe_summary is not None and len(probe_summary):
        main = probe_summary[probe_summary["control"].astype(str).isin(["none", ""])]
        for family, secs in probe_seconds.items():
            fam = main[main["family"] == family] if "family" in main.columns else main.iloc[0:0]
            if len(fam):
                width = float((fam["ci_high"] - fam["ci_low"]).median())
                rows.append(
                    ("probes", "probe family", family, secs, "median 95% CI width of Δ", width)
                )
    return pd.DataFrame(rows, columns=COST_COLUMNS)


def cost_figure(table: pd.DataFrame) -> plt.Figure:
    """One panel per stage: metric against seconds, each point a job, labelled by setting."""
    stages = list(dict.fromkeys(table["stage"]))
    fig, axes = plt.subplots(
        1, max(len(stages), 1), figsize=(4.2 * max(len(stages), 1), 3.6), squeeze=False
    )
    for ax, stage in zip(axes[0], stages, strict=False):
        part = table[table["stage"] == stage].dropna(subset=["seconds"])
        ax.scatter(part["seconds"], part["value"], s=18)
        for r in part.itertuples(index=False):
            ax.annotate(
                str(r.setting)[:28],
                (r.seconds, r.value),
                fontsize=6,
                xytext=(3, 3),
                textcoords="offset points",
            )
        ax.set_xlabel("wall seconds (benchmark file)")
        ax.set_ylabel("; ".join(dict.fromkeys(part["metric"]))[:60], fontsize=7)
        ax.set_title(stage, fontsize=9)
    fig.suptitle("Cost of accuracy: each point is one job", fontsize=10)
    fig.tight_layout()
    return fig
