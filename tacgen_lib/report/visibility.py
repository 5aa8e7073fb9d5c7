"""The report page *What vision sees* (`tacgen_lib.generate.visibility`): the accuracy with
which V decodes each visible factor of each simulated corpus, by each probe of the check (linear,
kernel, and the 2-layer probe on the gate's factors), beside the majority class's share; and
the sentence the findings page states from it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from tacgen_lib.corpus.looks import FACTORS
from tacgen_lib.report import format as fmt

if TYPE_CHECKING:
    import matplotlib.pyplot as plt

__all__ = ["PROBE_NAMES", "visibility_figure", "visibility_sentence", "visibility_table"]

_FACTOR_WORDS = {"appearance": "appearance class"}


def _ordered(rows: pd.DataFrame) -> pd.DataFrame:
    order = {f: i for i, f in enumerate(FACTORS)}
    return rows.assign(_f=rows["factor"].map(order)).sort_values(["corpus", "_f", "probe"])


#: Each probe of the check (`generate.visibility.PROBES`) as the report names it.
PROBE_NAMES = {"linear": "linear", "nonlinear": "kernel (RBF)", "mlp2": "2-layer"}


def visibility_table(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per corpus x factor: each probe's accuracy [95% CI] (a dash where the probe
    did not run on that factor), the majority class's share of the test rows, classes and
    rows."""
    out = []
    probes = [p for p in PROBE_NAMES if p in set(rows["probe"])]
    for (corpus, factor), g in _ordered(rows).groupby(["corpus", "factor"], sort=False):
        by = g.set_index("probe")
        r = g.iloc[0]
        row = {"corpus": corpus, "factor": _FACTOR_WORDS.get(factor, factor)}
        for probe in probes:
            row[f"{PROBE_NAMES[probe]} probe [95% CI]"] = (
                fmt.with_ci(
                    by.loc[probe, "score"], by.loc[probe, "ci_low"], by.loc[probe, "ci_high"]
                )
                if probe in by.index
                else fmt.MISSING
            )
        row.update(
            {
                "majority class": r["majority"],
                "classes": int(r["n_classes"]),
                "n train/test": f"{int(r['n'])}/{int(r['n_test'])}",
            }
        )
        out.append(row)
    return pd.DataFrame(out)


def visibility_figure(rows: pd.DataFrame) -> plt.Figure:
    """Accuracy per factor (bars: each probe of the check, whiskers: 95% CI; tick: the
    majority class's share), one panel per corpus."""
    import matplotlib.pyplot as plt

    from tacgen_lib.report.write import panel_grid

    corpora = sorted(rows["corpus"].unique())
    nrows, ncols, size = panel_grid(len(corpora), (3.4, 2.6), max_cols=3)
    fig, axes = plt.subplots(nrows, ncols, figsize=size, squeeze=False, constrained_layout=True)
    colours = {"linear": "#9ecae1", "nonlinear": "#3182bd", "mlp2": "#08519c"}
    probes = [p for p in PROBE_NAMES if p in set(rows["probe"])]
    width = 0.8 / len(probes)
    for ax, corpus in zip(axes.ravel(), corpora, strict=False):
        sub = _ordered(rows[rows["corpus"] == corpus])
        factors = list(dict.fromkeys(sub["factor"]))
        x = np.arange(len(factors))
        for k, probe in enumerate(probes):
            s = sub[sub["probe"] == probe].set_index("factor").reindex(factors)
            ax.bar(
                x + (k - (len(probes) - 1) / 2) * width,
                s["score"],
                width,
                color=colours[probe],
                label=f"{PROBE_NAMES[probe]} probe",
                yerr=[s["score"] - s["ci_low"], s["ci_high"] - s["score"]],
                capsize=2,
            )
        maj = sub.groupby("factor", sort=False)["majority"].first().loc[factors]
        ax.scatter(x, maj, marker="_", s=300, color="#d62728", label="majority class", zorder=3)
        ax.set_xticks(
            x,
            [_FACTOR_WORDS.get(f, f).replace(" class", "\nclass") for f in factors],
            fontsize=8,
        )
        ax.set_ylim(0, 1.05)
        ax.set_ylabel("test accuracy")
        ax.set_title(corpus, fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    for ax in axes.ravel()[len(corpora) :]:
        ax.set_visible(False)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=9)
    return fig


def visibility_sentence(rows: pd.DataFrame, corpus: str) -> str:
    """ "V sees colour …, texture …, appearance class …" on `corpus`: each factor's better
    probe's accuracy with its CI, against the majority class's share."""
    sub = _ordered(rows[rows["corpus"] == corpus])
    if sub.empty:
        return f"The visibility check has no row for {corpus}."
    parts = []
    for factor, g in sub.groupby("factor", sort=False):
        best = g.loc[g["score"].idxmax()]
        parts.append(
            f"{_FACTOR_WORDS.get(factor, factor)} {fmt.with_ci(best['score'], best['ci_low'], best['ci_high'])}"
            f" ({PROBE_NAMES.get(best['probe'], best['probe'])}; majority "
            f"{fmt.number(best['majority'])})"
        )
    return f"V sees, on {corpus}: " + "; ".join(parts) + "."
