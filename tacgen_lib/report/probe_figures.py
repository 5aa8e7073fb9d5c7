"""Figures of the probes stage, built from the probe summary and its confusion counts (pure
functions; the tables are `tacgen_lib.report.probes`').

- `forest_plot`: Delta with its 95% CI for every main comparison of one family, labelled by
  family / input / fusion and seeds; null-corpus families in their own colour.
- `forest_families`: the families that get a forest plot.
- `confusion_figures`: confusion matrices of the logistic probes (concat comparisons), per family.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from tacgen_lib.probes.rows import class_order
from tacgen_lib.report import PALETTE
from tacgen_lib.report import format as fmt
from tacgen_lib.report.probes import baselines_text, headline_rows, main_rows, seed_text

__all__ = ["confusion_figures", "forest_families", "forest_plot"]


def forest_plot(summary: pd.DataFrame, family: str, *, min_delta: float = 0.03) -> plt.Figure:
    """Delta with its 95% fixed-test bootstrap CI for every main comparison (heads' variant) of
    one probe family: one figure per family, so each is shown at full size in the viewer.

    Lines are labelled ``input / fusion  a~align seed s~probe seed``, with 0 (solid) and the
    paper's min Delta (dashed). Null-corpus families are drawn in grey. The marker says what
    the paper's criterion says of the line: a diamond where it is met, a filled circle where it
    is not, an open circle where it was not evaluated (its controls run on one comparison per
    family: concat, first seeds). Beside each line, the scores that size its Delta: V, V+T, the
    train-mean baseline and (where the manifest has shape and scale) the shape-only ceiling; a
    grey bar marks where Delta would be if V+T scored the shape-only ceiling.
    """
    rows = headline_rows(main_rows(summary))
    part = rows.loc[(rows["status"] == "ok") & (rows["family"] == family)].iloc[::-1]
    fig, ax = plt.subplots(figsize=(9.5, 1.9 + 0.34 * max(len(part), 1)))
    null = bool(part["null_corpus"].astype(bool).any()) if len(part) else False
    colour = PALETTE["grey"] if null else PALETTE["blue"]
    y = np.arange(len(part))
    for yi, (_, r) in zip(y, part.iterrows(), strict=True):
        ax.plot([r["ci_low"], r["ci_high"]], [yi, yi], color=colour, lw=1.6)
        met = r["criterion_met"]
        if fmt.is_missing(met):
            ax.plot([r["delta"]], [yi], marker="o", mfc="white", mec=colour, ms=6)
        else:
            ax.plot(
                [r["delta"]], [yi], marker="D" if met else "o", color=colour, ms=7 if met else 5
            )
        shape = r.get("visible_score", math.nan)
        if shape is not None and np.isfinite(shape):
            ax.plot([shape - r["v_score"]], [yi], marker="|", color="#999999", ms=9)
        ax.text(
            1.02, yi, baselines_text(r), transform=ax.get_yaxis_transform(), fontsize=8, va="center"
        )
    labels = [
        f"{r['input']} / {r['fusion']}  a~{seed_text(r['align_seed'])} s~{seed_text(r['probe_seed'])}"
        for _, r in part.iterrows()
    ]
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_ylim(-0.8, max(len(part), 1) - 0.2)
    ax.axvline(0.0, color="black", lw=0.8)
    ax.axvline(min_delta, color="black", lw=0.8, ls="--")
    metric = part["metric"].iloc[0] if len(part) else ""
    corpus = part["corpus"].iloc[0] if len(part) else ""
    ax.set_title(
        f"{family} ({corpus}, {metric}{', null corpus' if null else ''}): Δ = V+T − V with 95% "
        "CI\n◆ criterion met  ● not met  ○ not evaluated; dashed: the paper's min Δ",
        fontsize=9,
    )
    ax.set_xlabel("Δ = V+T − V, 95% fixed-test bootstrap CI", fontsize=8)
    ax.tick_params(axis="x", labelsize=8)
    ax.grid(axis="x", color="#dddddd", lw=0.6)
    fig.tight_layout()
    fig.subplots_adjust(right=0.64)
    return fig


def forest_families(summary: pd.DataFrame) -> list[str]:
    """The families `forest_plot` draws, in summary order."""
    rows = headline_rows(main_rows(summary))
    return list(dict.fromkeys(rows.loc[rows["status"] == "ok", "family"]))


def confusion_figures(confusion: pd.DataFrame) -> dict[str, plt.Figure]:
    """Confusion matrices (test rows) of the logistic probes' concat comparisons, V beside
    V+T: one figure per family (two comparisons side by side per row)."""
    conf = confusion.loc[confusion["fusion"] == "concat"] if len(confusion) else confusion
    if len(conf):
        conf = conf.loc[conf["t_variant"] == conf["heads_variant"]]
    out = {}
    if not len(conf):
        return out
    conf = conf.assign(_a=conf["align_seed"].fillna(-1))
    for fam, fam_rows in conf.groupby("family", sort=True):
        groups = list(fam_rows.groupby(["input", "_a", "probe_seed"], sort=True))
        per_row = 1 if len(groups) == 1 else 2
        nrows = -(-len(groups) // per_row)
        fig, axes = plt.subplots(
            nrows, 2 * per_row, figsize=(4.6 * per_row, min(2.9 * nrows, 8.6)), squeeze=False
        )
        for ax in axes.flat[2 * len(groups) :]:
            ax.axis("off")
        for k, ((inp, a, s), g) in enumerate(groups):
            classes = class_order(g["true"])
            row, col = divmod(k, per_row)
            for m_i, model in enumerate(("V", "V+T")):
                ax = axes[row, 2 * col + m_i]
                m = g.loc[g["model"] == model]
                mat = (
                    m.pivot_table(index="true", columns="pred", values="count", aggfunc="sum")
                    .reindex(index=classes, columns=classes)
                    .fillna(0)
                    .to_numpy()
                )
                top = max(mat.max(), 1)
                ax.imshow(mat, cmap="Blues", vmin=0, vmax=top)
                for (i, j), v in np.ndenumerate(mat):
                    colour = "white" if v > 0.6 * top else "black"
                    ax.text(j, i, f"{int(v)}", ha="center", va="center", fontsize=8, color=colour)
                ax.set_xticks(range(len(classes)), classes, fontsize=8, rotation=30)
                ax.set_yticks(range(len(classes)), classes, fontsize=8)
                ax.set_xlabel("predicted", fontsize=8)
                ax.set_ylabel("true", fontsize=8)
                acc = np.trace(mat) / max(mat.sum(), 1)
                ax.set_title(
                    f"{inp} a~{seed_text(a if a >= 0 else None)} s~{int(s)}\n"
                    f"{model}: accuracy {fmt.number(acc)}",
                    fontsize=8,
                )
        fig.suptitle(f"{fam}: confusion matrices on the test rows", fontsize=9)
        fig.tight_layout()
        out[str(fam)] = fig
    return out
