"""The cost-of-accuracy page (docs/cost.md): what each knob's settings buy, against their seconds.

Input is the points of every knob (`tacgen_lib.cost.points`, one table per knob). The page
has a figure (one row of panels per knob, one panel per metric: metric ± uncertainty against
wall seconds on a log axis, the default ringed, the Pareto front drawn), one sentence per knob
and metric written from the numbers (`report.pareto.knob_sentence`), the points as a table and
the marginal accuracy per extra minute between consecutive Pareto points.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import FuncFormatter, NullFormatter

from tacgen_lib.report import PALETTE
from tacgen_lib.report.pareto import knob_sentence, marginal_table, pareto_front
from tacgen_lib.report.tables import to_html
from tacgen_lib.report.write import panel_grid

__all__ = [
    "KNOB_UNITS",
    "cost_figures",
    "cost_page_html",
    "knob_sentences",
    "marginal_view",
    "points_view",
]

#: What a knob's setting labels count, for the sentences ("5,000 resamples").
KNOB_UNITS = {
    "align_steps": "steps",
    "align_n": "training pairs",
    "probe_bootstrap": "resamples",
    "probe_permutations": "permutations",
    "generate_steps": "sampling steps",
    "generate_sampler": "",
    "policy_width": "hidden units",
    "policy_epochs": "epochs",
}


def _label(x: str) -> str:
    try:
        v = float(x)
    except ValueError:
        return x
    return f"{v:,.0f}" if v.is_integer() and abs(v) >= 1000 else x


def knob_sentences(points: pd.DataFrame, units: Mapping[str, str] = KNOB_UNITS) -> list[str]:
    """One sentence per knob and metric, in the order of the points."""
    out = []
    for (knob, _metric), g in points.groupby(["knob", "metric"], sort=False):
        g = g.assign(label=g["label"].map(_label))
        out.append(knob_sentence(g, unit=units.get(knob, "")))
    return out


def points_view(points: pd.DataFrame) -> pd.DataFrame:
    """The points as the page's table: setting, metric [CI], seconds, front membership."""
    rows = []
    for (_knob, _metric), g in points.groupby(["knob", "metric"], sort=False):
        front = pareto_front(g["wall_s"], g["value"], str(g["direction"].iloc[0]))
        for on, r in zip(front, g.itertuples(index=False), strict=True):
            ci = f" [{r.ci_low:.4g}, {r.ci_high:.4g}]" if np.isfinite(r.ci_low) else ""
            rows.append(
                {
                    "knob": r.knob,
                    "stage": r.stage,
                    "setting": _label(r.label) + (" (default)" if r.is_default else ""),
                    "metric": f"{r.metric} ({r.direction} is better)",
                    "value [CI]": f"{r.value:.4g}{ci}",
                    "uncertainty": r.uncertainty,
                    "wall s": f"{r.wall_s:.1f}",
                    "CPU s": f"{r.cpu_s:.1f}",
                    "jobs": int(r.n_jobs),
                    "Pareto": "yes" if on else "",
                }
            )
    return pd.DataFrame(rows)


def marginal_view(points: pd.DataFrame) -> pd.DataFrame:
    """`marginal_table` rounded for the page."""
    t = marginal_table(points)
    if t.empty:
        return pd.DataFrame({"note": ["no knob has two settings on its Pareto front"]})
    return pd.DataFrame(
        {
            "knob": t["knob"],
            "metric": t["metric"],
            "from → to": [
                f"{_label(a)} → {_label(b)}" for a, b in zip(t["from"], t["to"], strict=True)
            ],
            "extra wall s": t["extra_s"].map("{:.1f}".format),
            "gain": t["gain"].map("{:+.4g}".format),
            "gain per extra minute": t["gain_per_min"].map("{:+.4g}".format),
            "gain inside the dearer point's interval": t["within_uncertainty"].map(
                {True: "yes (not measurable)", False: "no"}
            ),
        }
    )


def cost_page_html(
    points: pd.DataFrame, sentences: Sequence[str], *, title: str, note: str = ""
) -> str:
    """The page: a note, the sentences, then the points table (standalone HTML)."""
    page = to_html(points_view(points), title=title, mono=())
    intro = (
        (f"<p>{html.escape(note)}</p>" if note else "")
        + "<ul>"
        + "".join(f"<li>{html.escape(s)}</li>" for s in sentences)
        + "</ul>"
    )
    return page.replace("</h3>", "</h3>" + intro, 1)


def _offsets(x: np.ndarray) -> list[tuple[int, int, str]]:
    """Label offsets (points) and alignment for points at seconds `x` (in drawing order):
    above and below in turn; where neighbours crowd the x-axis (within 15 % of each other),
    to the right and left in turn, so no two labels of a cluster share a side."""
    order = np.argsort(x, kind="stable")
    out: list[tuple[int, int, str]] = [(4, 7, "left")] * len(x)
    for rank, i in enumerate(order):
        crowded = (
            any(
                j != i and np.isfinite(x[j]) and abs(np.log(x[j] / x[i])) < np.log(1.15)
                for j in range(len(x))
            )
            if np.isfinite(x[i]) and x[i] > 0
            else False
        )
        if crowded:
            out[i] = (7, -3, "left") if rank % 2 == 0 else (-7, -3, "right")
        else:
            out[i] = (4, 7, "left") if rank % 2 == 0 else (4, -11, "left")
    return out


def cost_figures(
    points: pd.DataFrame, stages: Mapping[str, str] | None = None
) -> dict[str, plt.Figure]:
    """One figure per knob (so each is shown whole and at full size), one panel per metric:
    value ± CI against wall seconds (log axis), each point labelled with its setting, the
    default ringed in red, the Pareto front a line."""
    out = {}
    for knob in dict.fromkeys(points["knob"]):
        part = points[points["knob"] == knob]
        metrics = list(dict.fromkeys(part["metric"]))
        nrows, ncols, figsize = panel_grid(len(metrics), (3.6, 3.2))
        fig, axes = plt.subplots(nrows, ncols, figsize=figsize, squeeze=False)
        for ax in axes.ravel()[len(metrics) :]:
            ax.set_visible(False)
        for ax, metric in zip(axes.ravel(), metrics, strict=False):
            g = part[part["metric"] == metric].sort_values("wall_s", kind="stable")
            direction = str(g["direction"].iloc[0])
            x, y = g["wall_s"].to_numpy(float), g["value"].to_numpy(float)
            lo, hi = g["ci_low"].to_numpy(float), g["ci_high"].to_numpy(float)
            err = np.vstack(
                [np.where(np.isfinite(lo), y - lo, 0), np.where(np.isfinite(hi), hi - y, 0)]
            )
            ax.errorbar(
                x,
                y,
                yerr=err,
                fmt="o",
                ms=4,
                color=PALETTE["blue"],
                ecolor=PALETTE["blue"],
                elinewidth=1,
                capsize=2,
                zorder=3,
            )
            front = pareto_front(x, y, direction)
            ax.plot(
                x[front],
                y[front],
                "-",
                color=PALETTE["green"],
                lw=1.2,
                alpha=0.8,
                label="Pareto front",
                zorder=2,
            )
            d = g["is_default"].to_numpy(bool)
            if d.any():
                ax.scatter(
                    x[d],
                    y[d],
                    s=110,
                    facecolors="none",
                    edgecolors=PALETTE["vermillion"],
                    lw=1.6,
                    label="default",
                    zorder=4,
                )
            for (dx, dy, ha), lab, xi, yi in zip(_offsets(x), g["label"], x, y, strict=True):
                ax.annotate(
                    _label(str(lab)),
                    (xi, yi),
                    xytext=(dx, dy),
                    textcoords="offset points",
                    ha=ha,
                    fontsize=8,
                    zorder=5,
                )
            ax.set_xscale("log")
            plain = FuncFormatter(lambda v, _: f"{v:g}")
            ax.xaxis.set_major_formatter(plain)
            span = np.nanmax(x) / max(np.nanmin(x), 1e-9) if len(x) else 1.0
            ax.xaxis.set_minor_formatter(plain if span < 10 else NullFormatter())
            if len(x) and np.nanmax(x) / max(np.nanmin(x), 1e-9) < 3:
                mid = float(np.sqrt(np.nanmax(x) * np.nanmin(x)))
                ax.set_xlim(mid / 2.0, mid * 2.0)  # a narrow range still shows as a factor
            ax.margins(x=0.15, y=0.2)
            ax.set_xlabel("wall seconds per run (benchmark files)", fontsize=8)
            arrow = "↑" if direction == "higher" else "↓"
            ax.set_ylabel(f"{metric} {arrow}", fontsize=8)
            ax.set_title(metric, fontsize=9)
            ax.tick_params(which="both", labelsize=8)
            ax.legend(fontsize=8, loc="best")
        stage = f" ({stages[knob]})" if stages and knob in stages else ""
        # on a one-panel figure the title takes two lines, else its ends are cut off
        sep = "\n" if len(metrics) == 1 else " "
        fig.suptitle(f"{knob}{stage}:{sep}each point one setting (± its uncertainty)", fontsize=10)
        fig.tight_layout()
        out[str(knob)] = fig
    return out
