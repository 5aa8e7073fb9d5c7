"""Figures for the Snakemake report (matplotlib, Agg backend, deterministic metadata)."""

from __future__ import annotations

import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from tacgen_lib.images import decode_png  # noqa: E402

__all__ = ["corpus_example_grid"]


def _pick_examples(
    samples: pd.DataFrame, splits: pd.DataFrame, n: int, seed: int = 0
) -> pd.DataFrame:
    """Up to n samples, spread over splits and strata, chosen at a fixed seed."""
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
    """Rows of RGB | raw tactile | background | tactile_proc, captioned with id, split, caption."""
    from tacgen_lib.preprocess import tactile_proc

    picks = _pick_examples(samples, splits, n)
    backgrounds = {
        r.sensor_id: decode_png(r.background, where=f"sensor {r.sensor_id}")
        for r in sensors.itertuples()
    }
    fig, axes = plt.subplots(
        len(picks),
        5,
        figsize=(12, 2.3 * len(picks)),
        squeeze=False,
        gridspec_kw={"width_ratios": [1.3, 1, 1, 1, 1]},
    )
    names = ["RGB", "tactile (raw)", "background", "tactile_proc"]
    for row, (_, s) in zip(axes, picks.iterrows(), strict=True):
        tac = decode_png(s["tactile"], where=s["sample_id"])
        bg = backgrounds[s["sensor_id"]]
        panels = [decode_png(s["rgb"], where=s["sample_id"]), tac, bg, tactile_proc(tac, bg)]
        label = (
            f"{s['sample_id']}\nsplit {s.get('split', '?')}, sensor {s['sensor_id']}\n\n"
            + "\n".join(textwrap.wrap(str(s["caption"]), 30))
        )
        row[0].axis("off")
        row[0].text(0.0, 0.5, label, fontsize=8, va="center", ha="left", transform=row[0].transAxes)
        for ax, img, name in zip(row[1:], panels, names, strict=True):
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(name, fontsize=8)
    fig.suptitle(f"corpus {title}: examples", fontsize=10)
    fig.tight_layout()
    return fig


def pretrain_curve_figure(curve: pd.DataFrame, *, title: str) -> plt.Figure:
    """DINO loss (and teacher entropy, where recorded) per epoch."""
    fig, ax = plt.subplots(figsize=(5, 3.2))
    if len(curve) == 0:
        ax.text(
            0.5, 0.5, "loaded from a checkpoint: no pretraining curve", ha="center", va="center"
        )
        ax.set_axis_off()
    else:
        ax.plot(curve["epoch"], curve["loss"], marker="o", label="DINO loss")
        ax.set_xlabel("epoch")
        ax.set_ylabel("loss")
        if "teacher_entropy" in curve.columns:
            ax2 = ax.twinx()
            ax2.plot(
                curve["epoch"],
                curve["teacher_entropy"],
                color="tab:orange",
                marker=".",
                label="teacher entropy",
            )
            ax2.set_ylabel("teacher entropy (nats)")
            ax2.legend(loc="upper right", fontsize=7)
        ax.legend(loc="upper left", fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig
