"""The corpus label figure (tacgen_lib.report.figures.label_distribution_figure): a discrete
label gets one bar per value, a continuous one (the natural design's density) a histogram."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
from matplotlib.patches import Rectangle

from tacgen_lib.report.figures import MAX_COUNT_BARS, label_distribution_figure


def _panel(fig, title: str):
    (ax,) = [a for a in fig.axes if a.get_visible() and a.get_title().startswith(title)]
    return ax


def test_discrete_labels_are_bars_and_a_continuous_density_is_a_histogram():
    rng = np.random.default_rng(0)
    n = 600
    samples = pd.DataFrame(
        {
            "shape": rng.choice(["box", "sphere", "cylinder"], n),
            "density": rng.uniform(300, 8000, n),  # one value per sample
            "hardness": rng.choice(["soft", "hard"], n),
            "mass": rng.uniform(0.05, 2.0, n),
        }
    )
    fig = label_distribution_figure(samples, title="natural")
    bars = [p for p in _panel(fig, "shape").patches if isinstance(p, Rectangle)]
    assert len(bars) == 3
    density = _panel(fig, "density")
    assert len(density.patches) == 30  # the histogram's bins, not 600 bars
    assert len(density.get_xticklabels()) < MAX_COUNT_BARS
    assert density.get_xlabel() == "density (kg/m³)"

    samples["density"] = rng.choice([500.0, 2000.0, 5000.0], n)
    fig = label_distribution_figure(samples, title="paired")
    assert len(_panel(fig, "density").patches) == 3
