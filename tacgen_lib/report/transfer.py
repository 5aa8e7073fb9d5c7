"""The report page *Transfer to a second sensor* (`tacgen_lib.probes.transfer`): balanced
accuracy of V and V+T on the transfer corpus's test objects for every heads view and heads
seed, Δ with its object-bootstrap CI per probe seed and over the seeds, the shuffled-touch
control beside each, and one sentence per view and heads seed from the numbers."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from tacgen_lib.probes.transfer import HEADS_VIEWS, beats_shuffled_control
from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt

__all__ = ["VIEW_LABELS", "transfer_figure", "transfer_sentences", "transfer_table"]

#: what each heads view is, for a reader
VIEW_LABELS = {
    "none": "no heads (frozen features)",
    "source": "heads from the first sensor's corpus (transfer)",
    "target": "heads retrained on the second sensor (upper reference)",
    "floor": "heads from the null corpus (floor)",
}
#: the same, short: table cells and axis ticks
VIEW_SHORT = {
    "none": "no heads",
    "source": "transfer",
    "target": "retrained (upper)",
    "floor": "null heads (floor)",
}


def _label(row) -> str:
    base = VIEW_LABELS.get(row.heads, row.heads)
    base = f"{base}: {row.heads_from}" if row.heads_from else base
    return f"{base}, heads seed {row.heads_seed}" if row.heads_seed else base


def _heads_from(rows: pd.DataFrame, view: str) -> str:
    names = rows.loc[rows["heads"] == view, "heads_from"]
    return f"({names.iloc[0]})" if len(names) and names.iloc[0] else "(frozen features)"


def _ordered(rows: pd.DataFrame) -> pd.DataFrame:
    rank = {v: i for i, v in enumerate(HEADS_VIEWS)}
    seed_rank = rows["probe_seed"].map(lambda s: 1e9 if s == "mean" else float(s))
    heads_rank = rows["heads_seed"].map(lambda s: -1.0 if s == "" else float(s))
    return (
        rows.assign(_v=rows["heads"].map(rank), _h=heads_rank, _s=seed_rank)
        .sort_values(["_v", "_h", "_s"], ignore_index=True)
        .drop(columns=["_v", "_h", "_s"])
    )


def transfer_table(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per heads view, heads seed and probe seed (the probe seeds' mean last), with the
    shuffled-touch control's Δ beside the real one."""
    r = _ordered(rows)
    return pd.DataFrame(
        {
            "heads": [VIEW_SHORT.get(x, x) for x in r["heads"]],
            "trained on": [x or "(frozen features)" for x in r["heads_from"]],
            "heads seed": [x or "–" for x in r["heads_seed"]],
            "probe seed": [
                f"mean of {x.n_seeds} ({x.positive_seeds}/{x.n_seeds} Δ > 0)"
                if x.probe_seed == "mean"
                else x.probe_seed
                for x in r.itertuples()
            ],
            "BA V": [fmt.number(x) for x in r["ba_v"]],
            "BA V+T": [fmt.number(x) for x in r["ba_vt"]],
            "Δ [95% CI]": [
                fmt.with_ci(x.delta, x.delta_ci_low, x.delta_ci_high, sign=True)
                for x in r.itertuples()
            ],
            "control: V+T shuffled Δ [95% CI]": [
                fmt.with_ci(
                    x.delta_shuffled, x.delta_shuffled_ci_low, x.delta_shuffled_ci_high, sign=True
                )
                for x in r.itertuples()
            ],
            "objects fit/test": [f"{x.n_fit_objects}/{x.n_test_objects}" for x in r.itertuples()],
        }
    )


def transfer_sentences(rows: pd.DataFrame, corpus: str) -> list[str]:
    """A sentence per heads view and heads seed from its probe seeds' mean row: the verdict on Δ, how many seeds
    are positive, whether the gain beats the shuffled-touch control, and, for a view whose
    projected V scores below the frozen features' V, that its Δ is measured against a weaker V
    (its V+T against the frozen V is given beside)."""
    means = _ordered(rows[rows["probe_seed"] == "mean"])
    if means.empty:
        return []
    first = means.iloc[0]
    raw = means[means["heads"] == "none"]
    raw_v = float(raw["ba_v"].iloc[0]) if len(raw) else None
    out = [
        f"Corpus {corpus}: {first.n_test_objects} test objects ({first.n_test_rows} contacts), "
        f"{first.n_seeds} probe seeds; chance balanced accuracy {fmt.number(first.chance)}."
    ]
    for x in means.itertuples():
        verdict = claims.delta_verdict(x.delta, x.delta_ci_low, x.delta_ci_high)
        shuffled = claims.interval_side(x.delta_shuffled_ci_low, x.delta_shuffled_ci_high)
        control = (
            "its interval lies above the shuffled-touch control's"
            if beats_shuffled_control(x.delta_ci_low, x.delta_shuffled_ci_high)
            else "it does not separate from the shuffled-touch control "
            f"(Δ {fmt.signed(x.delta_shuffled)}, CI {shuffled} 0)"
        )
        sentence = (
            f"{_label(x)}: {verdict} {x.positive_seeds}/{x.n_seeds} seeds positive; {control}."
        )
        if raw_v is not None and x.heads != "none" and x.ba_v < raw_v:
            sentence += (
                f" Its projected V ({fmt.number(x.ba_v)}) scores below the frozen features' V "
                f"({fmt.number(raw_v)}), so this Δ is measured against a weaker V: its V+T "
                f"against the frozen V is {fmt.signed(x.ba_vt - raw_v)}."
            )
        out.append(sentence)
    return out


def transfer_figure(rows: pd.DataFrame, corpus: str) -> plt.Figure:
    """Δ balanced accuracy per heads view, one column per heads seed: each probe seed's point
    with its CI, the probe seeds' mean (black) and the shuffled-touch control's mean (grey),
    with the 0 line."""
    r = _ordered(rows)
    views = [v for v in HEADS_VIEWS if v in set(r["heads"])]
    columns = [(v, h) for v in views for h in r.loc[r["heads"] == v, "heads_seed"].unique()]
    fig, ax = plt.subplots(figsize=(max(7.5, 1.3 * len(columns)), 4.4))
    for i, (view, heads_seed) in enumerate(columns):
        g = r[(r["heads"] == view) & (r["heads_seed"] == heads_seed)]
        seeds = g[g["probe_seed"] != "mean"]
        offsets = np.linspace(-0.25, 0.05, max(len(seeds), 1))
        for off, x in zip(offsets, seeds.itertuples(), strict=False):
            ax.errorbar(
                i + off,
                x.delta,
                yerr=[[x.delta - x.delta_ci_low], [x.delta_ci_high - x.delta]],
                fmt="o",
                ms=3,
                color="tab:blue",
                elinewidth=0.8,
                alpha=0.7,
            )
        mean = g[g["probe_seed"] == "mean"].iloc[0]
        ax.errorbar(
            i + 0.15,
            mean.delta,
            yerr=[[mean.delta - mean.delta_ci_low], [mean.delta_ci_high - mean.delta]],
            fmt="s",
            ms=5,
            color="black",
            label="mean over probe seeds" if i == 0 else None,
        )
        ax.errorbar(
            i + 0.3,
            mean.delta_shuffled,
            yerr=[
                [mean.delta_shuffled - mean.delta_shuffled_ci_low],
                [mean.delta_shuffled_ci_high - mean.delta_shuffled],
            ],
            fmt="D",
            ms=4,
            color="grey",
            label="shuffled touch (control)" if i == 0 else None,
        )
    ax.axhline(0.0, color="k", lw=0.8, ls="--")
    ax.set_xticks(range(len(columns)))
    ax.set_xticklabels(
        [
            f"{VIEW_SHORT[v]}\n{_heads_from(r, v)}" + (f"\nheads seed {h}" if h else "")
            for v, h in columns
        ],
        fontsize=8,
    )
    ax.set_ylabel("Δ balanced accuracy (V+T − V)")
    ax.set_title(f"{corpus}: mass tertiles on unseen objects of a second sensor", fontsize=10)
    ax.plot([], [], "o", color="tab:blue", ms=3, label="one probe seed (95 % CI)")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, frameon=False)
    fig.tight_layout()
    return fig
