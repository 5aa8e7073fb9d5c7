"""Tables and figures of the policy stage (pure functions over the policy summary tables).

- `success_table`: success with its 95 % CI per main cell, failure modes, and Δ vs V with the
  paired bootstrap CI; the null condition and the two references beside the result;
- `sweep_figure`: V-only success against hidden width per epoch budget, with the
  vision-only ceiling and the V+T-aligned line;
- `failure_figure`: stacked failure-mode bars per condition;
- `filmstrip`: RGB + both pads' squeeze and heft frames of one success and one failure per
  condition.
"""

from __future__ import annotations

from collections.abc import Mapping

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from tacgen_lib.io.images import decode_png
from tacgen_lib.policy.task import FAILURE_MODES
from tacgen_lib.report import PALETTE, claims
from tacgen_lib.report import format as fmt

__all__ = [
    "success_table",
    "success_with_ci",
    "sweep_figure",
    "sweep_notes",
    "failure_figure",
    "filmstrip",
]

COLOURS = {
    "success": PALETTE["green"],
    "slip": PALETTE["orange"],
    "crush": PALETTE["vermillion"],
    "drop": PALETTE["blue"],
    "miss": PALETTE["grey"],
}


def success_with_ci(r: Mapping) -> str:
    """A policy cell's success with its CI (`claims.proportion_with_ci`), from a summary row."""
    return claims.proportion_with_ci(r["success"], r["ci_low"], r["ci_high"], int(r["n_episodes"]))


def success_table(summary: pd.DataFrame, deltas: pd.DataFrame, main: list[str]) -> pd.DataFrame:
    s = summary.set_index("cell").loc[main].reset_index()
    d = deltas.set_index("row_id")
    rows = []
    for r in s.to_dict("records"):
        delta = d.loc[r["cell"]] if r["cell"] in d.index else None
        rows.append(
            {
                "condition": r["condition"],
                "cell": r["cell"],
                "episodes": r["n_episodes"],
                "success [95% CI]": success_with_ci(r),
                "Δ vs V [paired 95% CI]": fmt.MISSING
                if delta is None
                else fmt.with_ci(delta["delta"], delta["ci_low"], delta["ci_high"], sign=True),
                **{m: r[m] for m in FAILURE_MODES[1:]},
                "median force (N)": r["median_force"],
            }
        )
    return pd.DataFrame(rows)


def sweep_figure(sweep: pd.DataFrame) -> plt.Figure:
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for e, g in sweep.groupby("epochs"):
        ax.errorbar(
            g["hidden"],
            g["success"],
            yerr=g["sd"].fillna(0.0),
            marker="o",
            capsize=3,
            label=f"V-only, E={e}",
        )
    ceiling = float(sweep["vision_ceiling"].iloc[0])
    vt = float(sweep["vt_aligned"].iloc[0])
    ax.axhline(
        ceiling, color="k", ls="--", lw=1, label=f"vision-only ceiling {fmt.number(ceiling)}"
    )
    ax.axhline(vt, color=PALETTE["green"], ls="-", lw=1.5, label=f"V+T aligned {fmt.number(vt)}")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("MLP hidden width H")
    ax.set_ylabel("held-out success")
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title("V-only capacity sweep (error bars: sd over seeds)", fontsize=9)
    fig.tight_layout()
    return fig


def failure_figure(summary: pd.DataFrame, main: list[str]) -> plt.Figure:
    s = summary.set_index("cell").loc[main].reset_index()
    fig, ax = plt.subplots(figsize=(6, 3.4))
    bottom = np.zeros(len(s))
    n = s["n_episodes"].to_numpy()
    ok = (s["success"] * n).round().to_numpy()
    for mode in FAILURE_MODES:
        vals = ok if mode == "success" else s[mode].to_numpy()
        ax.bar(
            s["condition"], vals / np.maximum(n, 1), bottom=bottom, color=COLOURS[mode], label=mode
        )
        bottom += vals / np.maximum(n, 1)
    ax.set_ylabel("fraction of held-out episodes")
    ax.legend(fontsize=8, ncol=5, loc="upper center", bbox_to_anchor=(0.5, 1.18))
    ax.tick_params(axis="x", labelsize=8)
    fig.tight_layout()
    return fig


def filmstrip(
    episodes: pd.DataFrame, rollouts: Mapping[str, pd.DataFrame], frames: list[str]
) -> plt.Figure:
    """One success and one failure per condition (first in episode order): RGB + pad frames."""
    picks = []
    for cond, r in rollouts.items():
        for want in (True, False):
            hit = r[r["success"] == want]
            if len(hit):
                row = hit.iloc[0]
                picks.append((cond, row["episode_id"], row["mode"], row["grip_force"]))
    cols = 1 + len(frames)
    rows = max(len(picks), 1)
    side = min(1.3, 8.0 / rows, 8.2 / cols)  # every frame square; the whole fits the viewer
    fig, axes = plt.subplots(
        rows, cols, figsize=(side * cols + 1.6, side * rows + 0.6), squeeze=False
    )
    ep = episodes.set_index("episode_id")
    for i, (cond, eid, mode, force) in enumerate(picks):
        imgs = [ep.loc[eid, "rgb"], *(ep.loc[eid, f] for f in frames)]
        for j, data in enumerate(imgs):
            ax = axes[i, j]
            ax.imshow(decode_png(data))
            ax.set_xticks([])
            ax.set_yticks([])
            if j == 0:
                ax.set_ylabel(
                    f"{cond}\n{eid}\n{mode}, {fmt.number(force, 2)} N",
                    fontsize=8,
                    rotation=0,
                    ha="right",
                    va="center",
                )
            if i == 0:
                name = "RGB" if j == 0 else frames[j - 1].replace("tactile_", "")
                ax.set_title(name.replace("_", "\n", 1), fontsize=8)
    fig.tight_layout()
    return fig


def sweep_notes(summary: pd.DataFrame, sweep: pd.DataFrame) -> list[str]:
    """What the sweep table's reader needs beside it: where each V-only policy sits against the
    vision-only ceiling (`claims.ceiling_verdict`, with the main V cell's bootstrap CI)."""
    ceiling = float(sweep["vision_ceiling"].iloc[0])
    notes = [
        f"vision_ceiling {fmt.number(ceiling)}: the expected success of the best grip force "
        "given the visible size, over the task's prior (computed from the generative process, "
        "not re-scored on the held-out episodes); vision_ceiling_rollout is that force rolled "
        "out on the held-out episodes, with their sampling noise."
    ]
    v = summary.loc[summary["condition"] == "v"]
    for r in v.itertuples():
        notes.append(
            f"{r.cell}: " + claims.ceiling_verdict(r.success, r.ci_low, r.ci_high, ceiling)
        )
    return notes
