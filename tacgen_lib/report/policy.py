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

__all__ = ["success_table", "sweep_figure", "failure_figure", "filmstrip"]

COLOURS = {
    "success": "#4c956c",
    "slip": "#f4a259",
    "crush": "#bc4b51",
    "drop": "#5b8e7d",
    "miss": "#8d99ae",
}


def _ci(x: float, lo: float, hi: float, signed: bool = False) -> str:
    f = "{:+.3f}" if signed else "{:.3f}"
    return f"{f.format(x)} [{f.format(lo)}, {f.format(hi)}]"


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
                "success [95% CI]": _ci(r["success"], r["ci_low"], r["ci_high"]),
                "Δ vs V [paired 95% CI]": "—"
                if delta is None
                else _ci(delta["delta"], delta["ci_low"], delta["ci_high"], True),
                **{m: r[m] for m in FAILURE_MODES[1:]},
                "median force (N)": round(r["median_force"], 3),
            }
        )
    return pd.DataFrame(rows)


def sweep_figure(sweep: pd.DataFrame) -> plt.Figure:
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for e, g in sweep.groupby("epochs"):
        ax.errorbar(
            g["hidden"], g["success"], yerr=g["sd"], marker="o", capsize=3, label=f"V-only, E={e}"
        )
    ceiling = float(sweep["vision_ceiling"].iloc[0])
    vt = float(sweep["vt_aligned"].iloc[0])
    ax.axhline(ceiling, color="k", ls="--", lw=1, label=f"vision-only ceiling {ceiling:.3f}")
    ax.axhline(vt, color="#4c956c", ls="-", lw=1.5, label=f"V+T aligned {vt:.3f}")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("MLP hidden width H")
    ax.set_ylabel("held-out success")
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("V-only capacity sweep", fontsize=9)
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
    ax.legend(fontsize=7, ncol=5, loc="upper center", bbox_to_anchor=(0.5, 1.18))
    ax.tick_params(axis="x", labelsize=7)
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
    fig, axes = plt.subplots(
        max(len(picks), 1), cols, figsize=(1.3 * cols, 1.3 * max(len(picks), 1)), squeeze=False
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
                ax.set_ylabel(f"{cond}\n{eid}\n{mode}, {force:.2f} N", fontsize=5)
            if i == 0:
                ax.set_title("RGB" if j == 0 else frames[j - 1].replace("tactile_", ""), fontsize=5)
    fig.tight_layout()
    return fig
