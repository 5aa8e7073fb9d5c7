"""Tables and figures of the alignment stage, built from the per-cell metrics and curves.

This module owns the alignment summary (one row per grid cell: corpus, variant, seed, tau,
n_train, budget, retrieval on the held-out test split, chance levels, and the training wall
time read from the job's Snakemake benchmark file) and the report items made from it: the τ
ablation, the N-scaling table, the seed table (mean ± sd over seeds) and the training-curve
figure. Everything here is a pure function of its arguments (benchmark files are read by
`tacgen_lib.runtime.benchmarks`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from tacgen_lib.align.cell_names import CELL_COLUMNS
from tacgen_lib.align.retrieval import RETRIEVAL_METRICS
from tacgen_lib.report import claims
from tacgen_lib.report.write import panel_grid

__all__ = [
    "CELL_COLUMNS",
    "METRIC_COLUMNS",
    "SUMMARY_COLUMNS",
    "alignment_summary",
    "mean_sd",
    "seed_table",
    "tau_ablation_table",
    "n_scaling_table",
    "curve_figure",
]

METRIC_COLUMNS = RETRIEVAL_METRICS
SUMMARY_COLUMNS = (
    "cell",
    *CELL_COLUMNS,
    "budget",
    "val_loss",
    *METRIC_COLUMNS,
    "chance_top1",
    "chance_top5",
    "train_seconds",
)


def alignment_summary(metrics: pd.DataFrame, seconds: Mapping[str, float]) -> pd.DataFrame:
    """One row per grid cell with exactly `SUMMARY_COLUMNS`, sorted by cell.

    metrics: the per-cell metrics rows (key ``cell``); seconds: cell -> train wall time (s).
    A cell without a wall time, or a wall time without a cell, is an error naming the cell.
    """
    missing = [c for c in SUMMARY_COLUMNS if c not in metrics.columns and c != "train_seconds"]
    if missing:
        raise ValueError(f"alignment_summary: metrics rows lack column(s) {missing}")
    cells = set(metrics["cell"])
    if cells != set(seconds):
        odd = sorted(cells ^ set(seconds))[0]
        raise ValueError(
            f"alignment_summary: cell {odd!r} has metrics but no benchmark time, or the reverse"
        )
    out = metrics.copy()
    out["train_seconds"] = out["cell"].map(dict(seconds)).astype(float)
    return out[list(SUMMARY_COLUMNS)].sort_values("cell", ignore_index=True)


def _n_order(n: str) -> tuple[int, int]:
    return (1, 0) if str(n) == "all" else (0, int(n))


def mean_sd(values: Sequence[float] | np.ndarray, digits: int = 3) -> str:
    """``mean ± sd`` (sample sd, ddof=1) of values; a single value prints without ± ."""
    arr = np.asarray(values, dtype=float)
    if arr.size == 1:
        return f"{arr[0]:.{digits}f}"
    return f"{arr.mean():.{digits}f} ± {arr.std(ddof=1):.{digits}f}"


def _grouped(summary: pd.DataFrame, by: list[str], extra: Sequence[str] = ()) -> pd.DataFrame:
    rows = []
    for key, grp in summary.groupby(by, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(by, key, strict=True))
        row["seeds"] = int(grp["seed"].nunique())
        for col in (*METRIC_COLUMNS, *extra):
            row[col] = mean_sd(grp[col].to_numpy(), digits=1 if "rank" in col else 3)
        row["chance_top1"] = f"{grp['chance_top1'].mean():.3f}"
        row["chance_top5"] = f"{grp['chance_top5'].mean():.3f}"
        rows.append(row)
    return pd.DataFrame(rows)


def _ordered(summary: pd.DataFrame) -> pd.DataFrame:
    s = summary.copy()
    s["_n"] = s["n_train"].map(_n_order)
    s["_tau"] = s["tau"].astype(float)
    return s.sort_values(["corpus", "variant", "_tau", "_n", "seed"], kind="stable").drop(
        columns=["_n", "_tau"]
    )


def seed_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Retrieval on the held-out test split, mean ± sd over seeds, per corpus/variant/τ/N/budget."""
    return _grouped(
        _ordered(summary),
        ["corpus", "variant", "tau", "n_train", "budget"],
        extra=("val_loss", "train_seconds"),
    )


def tau_ablation_table(summary: pd.DataFrame, n_train: str) -> pd.DataFrame:
    """τ ablation: retrieval (mean ± sd over seeds) per corpus/variant/τ at one training size."""
    rows = summary[summary["n_train"].astype(str) == str(n_train)]
    if rows.empty:
        raise ValueError(f"tau_ablation_table: no cell has n_train={n_train!r}")
    return _grouped(_ordered(rows), ["corpus", "variant", "tau"], extra=("val_loss",))


def n_scaling_table(summary: pd.DataFrame, tau: str) -> pd.DataFrame:
    """N scaling: retrieval and train time (mean ± sd over seeds) per corpus/variant/N at one τ."""
    rows = summary[summary["tau"].astype(str) == str(tau)]
    if rows.empty:
        raise ValueError(f"n_scaling_table: no cell has tau={tau!r}")
    return _grouped(_ordered(rows), ["corpus", "variant", "n_train"], extra=("train_seconds",))


def curve_figure(curves: pd.DataFrame, *, n_train: str) -> plt.Figure:
    """Validation InfoNCE loss against optimiser step, one panel per corpus/variant at one N,
    one labelled line per (seed, τ); the marker shows each line's best (kept) step.

    curves: rows of the per-cell curve edges with the cell's corpus, variant, seed, tau and
    n_train columns added.
    """
    rows = curves[curves["n_train"].astype(str) == str(n_train)]
    if rows.empty:
        raise ValueError(f"curve_figure: no curve has n_train={n_train!r}")
    panels = sorted({(r.corpus, r.variant) for r in rows.itertuples()})
    nrows, ncols, figsize = panel_grid(len(panels), (4.7, 2.8))
    fig, axes = plt.subplots(nrows, ncols, figsize=figsize, squeeze=False, sharex=False)
    for ax in axes.flat[len(panels) :]:
        ax.set_visible(False)
    for ax, (corpus, variant) in zip(axes.flat, panels, strict=False):
        sub = rows[(rows["corpus"] == corpus) & (rows["variant"] == variant)]
        lines = sorted({(int(s), str(t)) for s, t in zip(sub["seed"], sub["tau"], strict=True)})
        falling = 0
        for seed, tau in lines:
            one = sub[(sub["seed"].astype(int) == seed) & (sub["tau"].astype(str) == tau)]
            one = one.sort_values("step")
            (line,) = ax.plot(one["step"], one["val_loss"], lw=1.2, label=f"seed {seed}, τ {tau}")
            best = one.loc[one["val_loss"].idxmin()]
            ax.plot([best["step"]], [best["val_loss"]], "o", color=line.get_color(), ms=4)
            falling += claims.still_falling(one["step"], one["val_loss"])
        note = f"\nval loss still falling at the end ({falling} of {len(lines)})" if falling else ""
        ax.set_title(
            f"{corpus} / {variant} / N={n_train}{note}",
            fontsize=9,
            color="#b22222" if falling else "black",
        )
        ax.set_xlabel("optimiser step")
        ax.set_ylabel("val InfoNCE loss")
        ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    return fig
