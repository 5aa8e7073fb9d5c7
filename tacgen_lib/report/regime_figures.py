"""The figures of the report page *Where generated touch helps* (`tacgen_lib.report.regime`):
Delta heatmaps over (rho, N_L) per pool size, and score against N_L per arm with the V
ceiling, the vision ceiling and real touch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from tacgen_lib.report import format as fmt
from tacgen_lib.report.generate import text_colour
from tacgen_lib.report.regime_arms import ARM_LABELS, arm_rows

if TYPE_CHECKING:  # pyplot is imported where a figure is drawn
    import matplotlib.pyplot as plt

__all__ = ["curves_figure", "heatmap_figure", "panel_axes"]


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
    (rho, N_L): a row of panels per target x reference, a column per pool size (the smallest
    and the largest where more ran: two columns fit the report's viewer, and the figure
    against the pool size, `regime_pool.pool_curve_figure`, shows every one); each cell: the
    mean Delta over seeds and how many seeds' CIs lie above / below 0."""
    import matplotlib.pyplot as plt

    targets = sorted(view["target"].unique())
    pools = sorted(view["n_pool"].unique())
    pools = pools if len(pools) <= 2 else [pools[0], pools[-1]]
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
        "Δ of V + T_gen (linear probe), mean over replicates; ↑/↓: replicates whose 95% CI is above/below 0",
        fontsize=9,
    )
    return fig


#: The curves of `curves_figure`, one a line: arm, probe, colour, line style.
_CURVE_ARMS = tuple(
    ((arm, probe), colour, style)
    for arm, probe, colour, style in map(
        str.split,
        """
        v linear #777777 -
        v nonlinear #222222 -
        look_oracle linear #ff7f0e -
        gen_mean linear #8c564b -
        v_tgen linear #d62728 -
        v_tgen nonlinear #d62728 --
        v_tgen_shuffled linear #ff9896 :
        distilled linear #1f77b4 -
        distilled nonlinear #1f77b4 --
        v_treal linear #2ca02c -
        v_ceiling nonlinear #17becf :
        vision_ceiling oracle #9467bd :
        """.strip().splitlines(),
    )
)


def panel_axes(rows: int, cols: int, panel: tuple[float, float], legend_height: float):
    """A figure of rows x cols panels of `panel` (width, height) inches each, with
    `legend_height` inches below them for the legend: (figure, axes[row][col])."""
    import matplotlib.pyplot as plt

    width, height = panel
    return plt.subplots(
        rows,
        cols,
        figsize=(width * cols, height * rows + legend_height),
        squeeze=False,
        constrained_layout=True,
    )


def curves_figure(view: pd.DataFrame) -> plt.Figure:
    """Score against N_L per arm at the largest pool, one panel per target x rho; bands: the
    mean over seeds of each arm's fixed-test 95% CI."""
    targets = sorted(view["target"].unique())
    rhos = sorted(view["rho"].unique())
    n_p = view["n_pool"].max()
    fig, axes = panel_axes(len(targets), len(rhos), (3.0, 2.8), legend_height=1.2)
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
