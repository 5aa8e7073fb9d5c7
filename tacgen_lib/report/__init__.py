"""The report: tables, figures and the cost of accuracy, built from the stages' edges.

Importing any module of this package selects matplotlib's Agg backend first (here, once), so
figures render headless on every machine, and the Okabe–Ito palette, which readers with the
common colour-vision deficiencies tell apart, as the colour cycle (`PALETTE`: figures that
name a colour take it from there too). `tacgen_lib.report.write` is the one way a figure or
table reaches disk: atomically, with no timestamps, so a rerun gives the same bytes.
"""

import matplotlib
from cycler import cycler

matplotlib.use("Agg")

#: Okabe & Ito (2008), "Color Universal Design": colour-blind-safe categorical colours
PALETTE = {
    "blue": "#0072B2",
    "orange": "#E69F00",
    "green": "#009E73",
    "vermillion": "#D55E00",
    "sky": "#56B4E9",
    "purple": "#CC79A7",
    "yellow": "#F0E442",
    "grey": "#999999",
}
matplotlib.rcParams["axes.prop_cycle"] = cycler(
    color=[PALETTE[k] for k in ("blue", "orange", "green", "vermillion", "sky", "purple")]
)
