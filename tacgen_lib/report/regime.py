"""The report page *Where generated touch helps* (`tacgen_lib.generate.regime`): Delta heatmaps
over (rho, N_L) per pool size, score against N_L per arm with the vision ceiling and real
touch, the table of every arm, the appearance check, and a sentence per panel generated from
the numbers.

Seeds are summarised, never averaged into a claim: a cell shows the mean over seeds and how
many seeds' fixed-test CIs lie above (or below) zero.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from tacgen_lib.report import format as fmt
from tacgen_lib.report.generate import text_colour

if TYPE_CHECKING:  # the figures import pyplot; the Findings table reads `arm_rows` without it
    import matplotlib.pyplot as plt

__all__ = [
    "ARM_LABELS",
    "appearance_table",
    "arm_rows",
    "curves_figure",
    "heatmap_figure",
    "hypothesis_sentences",
    "panel_sentences",
    "regime_table",
    "seed_view",
]

#: (arm, probe) -> the label a reader sees.
ARM_LABELS = {
    ("v", "linear"): "V (linear)",
    ("v", "nonlinear"): "V (nonlinear)",
    ("v_tgen", "linear"): "V + T_gen (linear)",
    ("v_tgen", "nonlinear"): "V + T_gen (nonlinear)",
    ("v_tgen_shuffled", "linear"): "V + T_gen, shuffled pool (linear)",
    ("distilled", "linear"): "distillation, V only (linear)",
    ("distilled", "nonlinear"): "distillation, V only (nonlinear)",
    ("v_treal", "linear"): "V + real T (linear)",
    ("vision_ceiling", "oracle"): "vision ceiling (oracle)",
}

_CELL = ["corpus", "rho", "n_labelled", "n_pool", "target", "arm", "probe"]


def arm_rows(frame: pd.DataFrame, arm: str, probe: str) -> pd.DataFrame:
    """The rows of one (arm, probe) of a regime summary or `seed_view`."""
    return frame[(frame["arm"] == arm) & (frame["probe"] == probe)]


def _side_counts(lo: pd.Series, hi: pd.Series) -> tuple[int, int]:
    return int((lo > 0).sum()), int((hi < 0).sum())


def seed_view(summary: pd.DataFrame) -> pd.DataFrame:
    """One row per cell x target x arm over seeds: mean score, CI bounds and Deltas, and per
    Delta how many seeds' CIs lie above / below 0 (``*_above``, ``*_below``), ``n_seeds``."""
    out = []
    for key, g in summary.groupby(_CELL, sort=True):
        row = dict(zip(_CELL, key, strict=True))
        row["metric"] = g["metric"].iloc[0]
        row["n_seeds"] = int(g["seed"].nunique())
        for col in ("score", "ci_low", "ci_high", "gap_closed"):
            row[col] = float(g[col].mean())
        for what in ("linear_v", "nonlinear_v", "distilled"):
            row[f"delta_vs_{what}"] = float(g[f"delta_vs_{what}"].mean())
            row[f"above_vs_{what}"], row[f"below_vs_{what}"] = _side_counts(
                g[f"ci_low_vs_{what}"], g[f"ci_high_vs_{what}"]
            )
        out.append(row)
    return pd.DataFrame(out)


def _counts(r: pd.Series, what: str) -> str:
    n, up, down = int(r["n_seeds"]), int(r[f"above_vs_{what}"]), int(r[f"below_vs_{what}"])
    return f"{up}/{n} ↑, {down}/{n} ↓"


def regime_table(view: pd.DataFrame) -> pd.DataFrame:
    """Every arm at the largest pool, the smallest and largest labelled sets, per rho and
    target: mean score [mean CI], the Deltas against linear V, nonlinear V and distillation
    (mean over seeds, with how many seeds' CIs lie above / below 0), the gap closed."""
    n_p = view["n_pool"].max()
    ls = sorted(view["n_labelled"].unique())
    sub = view[(view["n_pool"] == n_p) & view["n_labelled"].isin({ls[0], ls[-1]})]
    order = {k: i for i, k in enumerate(ARM_LABELS)}
    sub = sub.assign(_o=[order[(a, p)] for a, p in zip(sub["arm"], sub["probe"], strict=True)])
    sub = sub.sort_values(["target", "rho", "n_labelled", "_o"])
    return pd.DataFrame(
        {
            "target": sub["target"],
            "ρ": [f"{r:g}" for r in sub["rho"]],
            "N_L": sub["n_labelled"],
            "N_P": sub["n_pool"],
            "arm": [ARM_LABELS[(a, p)] for a, p in zip(sub["arm"], sub["probe"], strict=True)],
            "score [mean 95% CI]": [
                fmt.with_ci(r.score, r.ci_low, r.ci_high) for r in sub.itertuples()
            ],
            "Δ vs linear V": sub["delta_vs_linear_v"],
            "seeds' CI vs linear V": [_counts(r, "linear_v") for _, r in sub.iterrows()],
            "Δ vs nonlinear V": sub["delta_vs_nonlinear_v"],
            "seeds' CI vs nonlinear V": [_counts(r, "nonlinear_v") for _, r in sub.iterrows()],
            "Δ vs distillation": sub["delta_vs_distilled"],
            "seeds' CI vs distillation": [_counts(r, "distilled") for _, r in sub.iterrows()],
            # the ceiling is an oracle, not an arm that closes the gap to real touch
            "gap closed": sub["gap_closed"].where(sub["arm"] != "vision_ceiling"),
        }
    )


def appearance_table(appearance: pd.DataFrame) -> pd.DataFrame:
    """Appearance-class accuracy of the linear and the nonlinear V probe, per corpus and seed
    checked (the DAG checks one)."""
    a = appearance.sort_values(["rho", "seed", "probe"])
    return pd.DataFrame(
        {
            "corpus": a["corpus"],
            "ρ": [f"{r:g}" for r in a["rho"]],
            "seed": a["seed"],
            "probe on V": a["probe"],
            "appearance-class accuracy [95% CI]": [
                fmt.with_ci(r.score, r.ci_low, r.ci_high) for r in a.itertuples()
            ],
            "majority class": a["chance"],
            "n train/test": [f"{r.n_train}/{r.n_test}" for r in a.itertuples()],
        }
    )


def _grid(view: pd.DataFrame, target: str, n_pool: int, col: str):
    """Delta `col` of V + T_gen (linear probe) as a (N_L, rho) matrix with cell texts."""
    sub = arm_rows(
        view[(view["target"] == target) & (view["n_pool"] == n_pool)], "v_tgen", "linear"
    )
    rhos = sorted(sub["rho"].unique())
    ls = sorted(sub["n_labelled"].unique())
    mat = np.full((len(ls), len(rhos)), np.nan)
    txt = [["" for _ in rhos] for _ in ls]
    what = col.removeprefix("delta_vs_")
    for _, r in sub.iterrows():
        i, j = ls.index(r["n_labelled"]), rhos.index(r["rho"])
        mat[i, j] = r[col]
        txt[i][j] = (
            f"{fmt.signed(r[col])}\n{int(r[f'above_vs_{what}'])}↑ {int(r[f'below_vs_{what}'])}↓"
            f" of {int(r['n_seeds'])}"
        )
    return rhos, ls, mat, txt


def heatmap_figure(view: pd.DataFrame) -> plt.Figure:
    """Delta of V + T_gen (linear probe) against linear V and against nonlinear V over
    (rho, N_L): a row of panels per target x reference, a column per pool size; each cell:
    the mean Delta over seeds and how many seeds' CIs lie above / below 0."""
    import matplotlib.pyplot as plt

    targets = sorted(view["target"].unique())
    pools = sorted(view["n_pool"].unique())
    refs = (("delta_vs_linear_v", "linear V"), ("delta_vs_nonlinear_v", "nonlinear V"))
    rows = [(t, col, name) for t in targets for col, name in refs]
    fig, axes = plt.subplots(
        len(rows),
        len(pools),
        figsize=(3.4 * len(pools) + 1.0, 2.0 * len(rows) + 0.5),
        squeeze=False,
        constrained_layout=True,
    )
    cmap = plt.get_cmap("RdBu")
    for i, (target, col, name) in enumerate(rows):
        sub = view[view["target"] == target]
        lim = float(np.nanmax(np.abs(sub[[c for c, _ in refs]].to_numpy()))) or 1.0
        im = None
        for j, n_p in enumerate(pools):
            ax = axes[i][j]
            rhos, ls, mat, txt = _grid(view, target, n_p, col)
            im = ax.imshow(mat, cmap=cmap, vmin=-lim, vmax=lim, aspect="auto", origin="lower")
            for a in range(len(ls)):
                for b in range(len(rhos)):
                    if np.isfinite(mat[a, b]):
                        ax.text(
                            b,
                            a,
                            txt[a][b],
                            ha="center",
                            va="center",
                            fontsize=8,
                            color=text_colour(cmap((mat[a, b] + lim) / (2 * lim))),
                        )
            ax.set_xticks(range(len(rhos)), [f"{r:g}" for r in rhos])
            ax.set_yticks(range(len(ls)), [str(n) for n in ls])
            ax.set_xlabel("ρ (appearance = material)", fontsize=8)
            ax.set_ylabel("N_L", fontsize=8)
            ax.set_title(f"{target}, N_P = {n_p}: V + T_gen − {name}", fontsize=8)
        fig.colorbar(im, ax=list(axes[i]), shrink=0.9, label=f"Δ {sub['metric'].iloc[0]}")
    fig.suptitle(
        "Δ of V + T_gen (linear probe), mean over seeds; ↑/↓: seeds whose 95% CI is above/below 0",
        fontsize=9,
    )
    return fig


_CURVE_ARMS = (
    (("v", "linear"), "#777777", "-"),
    (("v", "nonlinear"), "#222222", "-"),
    (("v_tgen", "linear"), "#d62728", "-"),
    (("v_tgen", "nonlinear"), "#d62728", "--"),
    (("v_tgen_shuffled", "linear"), "#ff9896", ":"),
    (("distilled", "linear"), "#1f77b4", "-"),
    (("distilled", "nonlinear"), "#1f77b4", "--"),
    (("v_treal", "linear"), "#2ca02c", "-"),
    (("vision_ceiling", "oracle"), "#9467bd", ":"),
)


def curves_figure(view: pd.DataFrame) -> plt.Figure:
    """Score against N_L per arm at the largest pool, one panel per target x rho; bands: the
    mean over seeds of each arm's fixed-test 95% CI."""
    import matplotlib.pyplot as plt

    targets = sorted(view["target"].unique())
    rhos = sorted(view["rho"].unique())
    n_p = view["n_pool"].max()
    fig, axes = plt.subplots(
        len(targets),
        len(rhos),
        figsize=(3.0 * len(rhos), 2.8 * len(targets) + 1.2),
        squeeze=False,
        constrained_layout=True,
    )
    for i, target in enumerate(targets):
        for j, rho in enumerate(rhos):
            ax = axes[i][j]
            sub = view[(view["target"] == target) & (view["rho"] == rho) & (view["n_pool"] == n_p)]
            for (arm, probe), colour, style in _CURVE_ARMS:
                s = arm_rows(sub, arm, probe).sort_values("n_labelled")
                if s.empty:
                    continue
                ax.plot(
                    s["n_labelled"],
                    s["score"],
                    color=colour,
                    linestyle=style,
                    marker="o",
                    markersize=3,
                    label=ARM_LABELS[(arm, probe)],
                )
                ax.fill_between(
                    s["n_labelled"], s["ci_low"], s["ci_high"], color=colour, alpha=0.08
                )
            ax.set_xscale("log", base=2)
            ticks = sorted(view["n_labelled"].unique())
            ax.set_xticks(ticks, [str(t) for t in ticks])
            ax.minorticks_off()
            ax.set_xlabel("N_L labelled rows")
            ax.set_ylabel(sub["metric"].iloc[0] if len(sub) else "")
            ax.set_title(f"{target}, ρ = {rho:g}, N_P = {n_p}", fontsize=9)
            ax.grid(alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=9)
    return fig


def _delta_words(r: pd.Series, what: str) -> str:
    """A `seed_view` row's mean Delta against `what` (linear_v | nonlinear_v | distilled) and
    how many seeds' CIs lie above or below 0, in words."""
    d, n = r[f"delta_vs_{what}"], int(r["n_seeds"])
    up, down = int(r[f"above_vs_{what}"]), int(r[f"below_vs_{what}"])
    if up:
        side = f"CI above 0 in {up} of {n} seeds"
    elif down:
        side = f"CI below 0 in {down} of {n} seeds"
    else:
        side = f"CI includes 0 in each of {n} seeds"
    return f"{fmt.signed(d)} ({side})"


def panel_sentences(view: pd.DataFrame) -> list[str]:
    """One sentence per heatmap panel (target x pool size), read from the numbers: where V +
    T_gen gains over linear V, whether that survives nonlinear V and distillation."""
    out = []
    gen = arm_rows(view, "v_tgen", "linear")
    for (target, n_p), g in gen.groupby(["target", "n_pool"], sort=True):
        wins = g[g["above_vs_linear_v"] == g["n_seeds"]]
        if wins.empty:
            out.append(
                f"{target}, N_P = {n_p}: V + T_gen (linear probe) beats linear V with its CI above "
                "0 in every seed in no cell of ρ × N_L."
            )
            continue
        cells = ", ".join(f"ρ = {r.rho:g} / N_L = {r.n_labelled}" for r in wins.itertuples())
        survive_nl = wins[wins["above_vs_nonlinear_v"] == wins["n_seeds"]]
        survive_gd = wins[wins["above_vs_distilled"] == wins["n_seeds"]]
        out.append(
            f"{target}, N_P = {n_p}: V + T_gen (linear probe) beats linear V in every seed at "
            f"{cells}; of these, {len(survive_nl)} also beat nonlinear V and {len(survive_gd)} "
            "beat generalised distillation (a V-only student of the same pool) in every seed."
        )
    return out


def hypothesis_sentences(view: pd.DataFrame) -> list[str]:
    """The issue's four expectations, each tested on the numbers and stated as measured."""
    out = []
    rhos = sorted(view["rho"].unique())
    ls = sorted(view["n_labelled"].unique())
    n_p = view["n_pool"].max()
    built_on_v = view[~view["arm"].isin(["v_treal", "vision_ceiling"])]
    # H1: at rho = 0 every arm matches nonlinear V
    r0 = built_on_v[
        (built_on_v["rho"] == rhos[0])
        & ~((built_on_v["arm"] == "v") & (built_on_v["probe"] == "nonlinear"))
    ]
    off = r0[
        (r0["above_vs_nonlinear_v"] == r0["n_seeds"])
        | (r0["below_vs_nonlinear_v"] == r0["n_seeds"])
    ]
    above = int((off["above_vs_nonlinear_v"] == off["n_seeds"]).sum())
    out.append(
        f"H1 (ρ = {rhos[0]:g}: no arm built on V beats nonlinear V): {above} of {len(r0)} "
        f"arm × cell rows beat it with the CI above 0 in every seed; "
        f"{len(off) - above} fall below it in every seed."
    )
    # H2: at the largest rho, smallest N_L, largest pool, V + T_gen beats linear V
    top = view[(view["rho"] == rhos[-1]) & (view["n_labelled"] == ls[0]) & (view["n_pool"] == n_p)]
    for probe in ("linear", "nonlinear"):
        g = arm_rows(top, "v_tgen", probe)
        if g.empty:
            continue
        r = g.iloc[0]
        out.append(
            f"H2 (ρ = {rhos[-1]:g}, N_L = {ls[0]}, N_P = {n_p}: V + T_gen beats linear V), "
            f"{probe} probe: Δ vs linear V "
            f"{_delta_words(r, 'linear_v')}"
            f"; vs nonlinear V "
            f"{_delta_words(r, 'nonlinear_v')}"
            f"; vs distillation "
            f"{_delta_words(r, 'distilled')}."
        )
    # H3: the gain shrinks as N_L grows
    g = arm_rows(view[(view["rho"] == rhos[-1]) & (view["n_pool"] == n_p)], "v_tgen", "linear")
    for target, t in g.groupby("target", sort=True):
        t = t.sort_values("n_labelled")
        d = t["delta_vs_linear_v"].to_numpy()
        if d[0] <= 0:
            verdict = (
                f"untestable: there is no gain at N_L = {ls[0]} to shrink "
                f"({fmt.signed(d[0])}; {fmt.signed(d[-1])} at N_L = {ls[-1]})"
            )
        else:
            trend = "shrinks" if d[-1] < d[0] else "does not shrink"
            verdict = (
                f"the Δ of V + T_gen over linear V {trend} from {fmt.signed(d[0])} at N_L = "
                f"{ls[0]} to {fmt.signed(d[-1])} at N_L = {ls[-1]}"
            )
        out.append(f"H3 ({target}, ρ = {rhos[-1]:g}, N_P = {n_p}): {verdict}.")
    # the pool without generation: distillation against linear V and against V + T_gen
    for target, t in top.groupby("target", sort=True):
        d = arm_rows(t, "distilled", "linear").iloc[0]
        gen = arm_rows(t, "v_tgen", "linear").iloc[0]
        pool_only = gen["above_vs_distilled"] < gen["n_seeds"]
        out.append(
            f"The pool without generation ({target}, ρ = {rhos[-1]:g}, N_L = {ls[0]}, N_P = "
            f"{n_p}): generalised distillation (linear student on V) vs linear V "
            f"{_delta_words(d, 'linear_v')}"
            f"; V + T_gen vs distillation "
            f"{_delta_words(gen, 'distilled')}"
            + (
                ": generation adds nothing the pool does not give without it."
                if pool_only
                else ": generation beats the V-only use of the pool in every seed."
            )
        )
    # H4: no arm built on V exceeds the vision ceiling
    ceiling = view[view["arm"] == "vision_ceiling"].set_index(
        ["corpus", "rho", "n_labelled", "n_pool", "target"]
    )
    exceed = []
    for r in built_on_v.itertuples():
        c = ceiling.loc[(r.corpus, r.rho, r.n_labelled, r.n_pool, r.target)]
        if r.ci_low > c["ci_high"]:
            exceed.append(f"{ARM_LABELS[(r.arm, r.probe)]} at ρ = {r.rho:g}, N_L = {r.n_labelled}")
    out.append(
        "H4 (no arm built on V exceeds the vision ceiling): "
        + (
            "holds: no arm's mean CI lies above the ceiling's."
            if not exceed
            else f"fails in {len(exceed)} rows, e.g. {exceed[0]}."
        )
    )
    return out


def findings_notes(view: pd.DataFrame, appearance: pd.DataFrame) -> list[str]:
    """The page's sentences: the hypotheses, one per panel, the appearance check (measured on
    one corpus of the rho grid: the class -> frame process is the same at every rho)."""
    app = appearance.groupby(["corpus", "rho", "probe"])["score"].mean().unstack("probe")
    check = "; ".join(
        f"{corpus} (ρ = {rho:g}): linear {fmt.number(r.get('linear'))}, "
        f"nonlinear {fmt.number(r.get('nonlinear'))}"
        for (corpus, rho), r in app.iterrows()
    )
    return [
        *hypothesis_sentences(view),
        *panel_sentences(view),
        f"Appearance class from V, linear against nonlinear probe (accuracy): {check}; the "
        "appearance class and what it looks like do not depend on ρ, so one corpus of the grid "
        "is checked.",
    ]


def findings_table(notes: Sequence[str]) -> pd.DataFrame:
    return pd.DataFrame({"finding (generated from the numbers)": list(notes)})
