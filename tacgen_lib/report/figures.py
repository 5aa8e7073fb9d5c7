"""Figures for the Snakemake report (matplotlib, Agg backend, deterministic metadata)."""

from __future__ import annotations

import textwrap

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from tacgen_lib.io.images import decode_png
from tacgen_lib.report import PALETTE
from tacgen_lib.report import format as fmt
from tacgen_lib.report.format import numeric_order
from tacgen_lib.report.write import panel_grid

__all__ = ["corpus_example_grid"]


#: The seed the example grid picks its samples at (`corpus_example_grid`).
EXAMPLES_SEED = 0


def _pick_examples(samples: pd.DataFrame, splits: pd.DataFrame, n: int, seed: int) -> pd.DataFrame:
    """Up to n samples, spread over splits and strata, chosen at `seed`."""
    merged = samples.merge(splits[["sample_id", "split"]], on="sample_id", how="left")
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(merged))
    merged = merged.iloc[order]
    # round-robin over strata so every class shows up before any repeats
    merged["_rank"] = merged.groupby("stratum").cumcount()
    strata = merged["stratum"].unique()
    merged["_order"] = merged["stratum"].map(
        dict(zip(strata, rng.permutation(len(strata)), strict=True))
    )
    return merged.sort_values(["_rank", "_order"], kind="stable").head(n)


def corpus_example_grid(
    samples: pd.DataFrame, sensors: pd.DataFrame, splits: pd.DataFrame, *, n: int, title: str
) -> plt.Figure:
    """Examples as RGB | raw tactile | background | tactile_proc (tactile − background + 128),
    each captioned with its id, split, sensor and caption; two examples per row. A sample
    whose sensor has no background (a real corpus's row without one) shows blank panels
    for the two."""
    from tacgen_lib.preprocess.background import tactile_proc

    picks = _pick_examples(samples, splits, n, EXAMPLES_SEED)
    backgrounds = {
        r.sensor_id: decode_png(r.background, where=f"sensor {r.sensor_id}")
        for r in sensors.itertuples()
    }
    # two examples side by side per row, so eight fit the viewer at full size
    per_row = 1 if len(picks) == 1 else 2
    nrows = -(-len(picks) // per_row)
    fig, axes = plt.subplots(
        nrows,
        5 * per_row,
        figsize=(9.5 if per_row == 2 else 5.0, 1.45 * nrows + 0.55),
        squeeze=False,
        gridspec_kw={"width_ratios": [1.7, 1, 1, 1, 1] * per_row},
    )
    names = ["RGB", "raw", "background", "subtracted"]
    for ax in axes.flat:
        ax.axis("off")
    for k, (_, s) in enumerate(picks.iterrows()):
        r, c = divmod(k, per_row)
        row = axes[r, 5 * c : 5 * c + 5]
        tac = decode_png(s["tactile"], where=s["sample_id"])
        bg = backgrounds.get(s["sensor_id"])  # None: a real sample whose background is missing
        blank = np.full_like(tac, 255)
        panels = [
            decode_png(s["rgb"], where=s["sample_id"]),
            tac,
            blank if bg is None else bg,
            blank if bg is None else tactile_proc(tac, bg),
        ]
        caption = textwrap.wrap(str(s["caption"]), 19)
        sensor = str(s["sensor_id"]).rsplit("/", 1)[-1]
        label = (
            f"{str(s['sample_id']).rsplit('-', 1)[-1]} ({s.get('split', '?')})\n{sensor}\n"
            + "\n".join(caption[:4] + (["…"] if len(caption) > 4 else []))
        )
        row[0].text(0.0, 0.5, label, fontsize=8, va="center", ha="left", transform=row[0].transAxes)
        for ax, img, name in zip(row[1:], panels, names, strict=True):
            ax.axis("on")
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(name, fontsize=8)
    # fixed margins, not tight_layout: the caption text may run into its cell's right edge
    # without shrinking every image to make room for it
    top = 1 - 0.55 / fig.get_figheight()
    fig.subplots_adjust(left=0.01, right=0.99, top=top, bottom=0.02, wspace=0.06, hspace=0.15)
    fig.suptitle(
        f"corpus {title}: examples (sample number, split, sensor, caption); background "
        "subtracted: tactile − background + 128",
        fontsize=9,
    )
    return fig


def pretrain_curve_figure(
    curve: pd.DataFrame,
    *,
    title: str,
    empty_note: str = "loaded from a checkpoint: no pretraining curve",
    loss: str = "DINO loss",
) -> plt.Figure:
    """The pretraining loss (named `loss`: DINO, MAE or SimCLR) and the teacher entropy, where
    recorded, per epoch; `empty_note` says why an empty curve is empty (a checkpoint, or
    pretraining turned off)."""
    fig, ax = plt.subplots(figsize=(5, 3.2))
    if len(curve) == 0:
        ax.text(0.5, 0.5, empty_note, ha="center", va="center")
        ax.set_axis_off()
    else:
        ax.plot(curve["epoch"], curve["loss"], marker="o", label=loss)
        ax.set_xlabel("epoch")
        ax.set_ylabel("loss")
        if "teacher_entropy" in curve.columns:
            ax2 = ax.twinx()
            ax2.plot(
                curve["epoch"],
                curve["teacher_entropy"],
                color=PALETTE["orange"],
                marker=".",
                label="teacher entropy",
            )
            ax2.set_ylabel("teacher entropy (nats)")
            ax2.legend(loc="upper right", fontsize=8)
        ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


#: A label column with more distinct values than this is drawn as a histogram.
MAX_COUNT_BARS = 20
HIST_UNITS = {"mass": "mass (kg)", "density": "density (kg/m³)", "hardness": "hardness"}


def label_distribution_figure(samples: pd.DataFrame, *, title: str) -> plt.Figure:
    """Label distributions of a corpus and its force bands (p05–p95 around p50 against mass).

    Panels appear for the label columns the corpus has: shape, density and hardness counts,
    a mass histogram, and force_p50 with its p05/p95 band per sample against mass (with the
    m·g line). A real corpus without physical labels shows its hardness and top adjectives.
    """
    panels = []
    for col in ("shape", "density", "hardness"):
        if col in samples.columns and samples[col].notna().any():
            # a continuous label (the natural design's density) is a histogram, not one bar
            # per value
            discrete = samples[col].nunique() <= MAX_COUNT_BARS
            panels.append(("counts" if discrete else "hist", col))
    if "mass" in samples.columns and samples["mass"].notna().any():
        panels.append(("hist", "mass"))
    if {"force_p05", "force_p50", "force_p95", "mass"} <= set(samples.columns) and samples[
        "force_p50"
    ].notna().any():
        panels.append(("bands", "force"))
    if not panels and "adjectives" in samples.columns:
        panels.append(("adjectives", "adjectives"))
    nrows, ncols, figsize = panel_grid(max(len(panels), 1), (3.1, 2.9))
    fig, axes = plt.subplots(nrows, ncols, figsize=figsize, squeeze=False)
    for ax in axes.flat[len(panels) :]:
        ax.set_visible(False)
    for ax, (kind, col) in zip(axes.flat, panels, strict=False):
        if kind == "counts":
            counts = samples[col].value_counts()
            counts = counts.reindex(numeric_order(counts.index))  # 500, 2000, 5000: by value
            ax.bar(
                [
                    fmt.cell(x, integral=True)
                    if isinstance(x, float) and float(x).is_integer()
                    else str(x)
                    for x in counts.index
                ],
                counts.to_numpy(),
            )
            ax.tick_params(axis="x", labelrotation=45, labelsize=8)
            ax.set_title(f"{col} (samples)", fontsize=9)
        elif kind == "hist":
            ax.hist(samples[col].dropna().to_numpy(dtype=np.float64), bins=30)
            ax.set_xlabel(HIST_UNITS.get(col, col))
            ax.set_title(f"{col} (samples)" if col != "mass" else "mass", fontsize=9)
        elif kind == "bands":
            d = samples.dropna(subset=["mass", "force_p50"]).sort_values("mass")
            ax.errorbar(
                d["mass"],
                d["force_p50"],
                yerr=[d["force_p50"] - d["force_p05"], d["force_p95"] - d["force_p50"]],
                fmt=".",
                ms=2,
                elinewidth=0.5,
                alpha=0.6,
                label="p50 with p05–p95",
            )
            m = np.linspace(0, d["mass"].max(), 10)
            ax.plot(m, 9.81 * m, "k--", lw=0.8, label="m·g")
            ax.set_xlabel("mass (kg)")
            ax.set_ylabel("contact force (N)")
            ax.set_title("force bands", fontsize=9)
            ax.legend(fontsize=8)
        else:
            words = (
                pd.Series([w for adj in samples[col] for w in list(adj)]).value_counts().head(12)
            )
            ax.barh(words.index[::-1], words.to_numpy()[::-1])
            ax.set_title("top adjectives", fontsize=9)
    fig.suptitle(f"corpus {title}: labels", fontsize=10)
    fig.tight_layout()
    return fig
