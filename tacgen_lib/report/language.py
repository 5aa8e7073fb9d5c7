"""The report page *Touch to language* (`tacgen_lib.language.adapter`): forced-choice accuracy
of real, generated and shuffled generated touch per corpus and attribute, the margin of
generated over shuffled with its paired CI, and a sentence per corpus from the numbers."""

from __future__ import annotations

import pandas as pd

from tacgen_lib.language.adapter import PAPER_MARGINS
from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt

__all__ = ["language_sentences", "language_table"]

_INPUT_LABELS = {
    "real": "real touch",
    "generated": "generated touch",
    "shuffled_generated": "generated, rows shuffled",
}


def language_table(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per corpus x attribute x input: accuracy [95% CI], the margin over shuffled
    generated touch [paired 95% CI], the majority-word rate (the accuracy of always choosing
    the train rows' commoner word)."""
    order = {k: i for i, k in enumerate(_INPUT_LABELS)}
    r = rows.assign(_o=rows["input"].map(order)).sort_values(["corpus", "attribute", "_o"])
    return pd.DataFrame(
        {
            "corpus": r["corpus"],
            "attribute": r["attribute"],
            "tactile input": r["input"].map(_INPUT_LABELS),
            "accuracy [95% CI]": [
                fmt.with_ci(x.accuracy, x.ci_low, x.ci_high) for x in r.itertuples()
            ],
            "Δ vs shuffled generated [paired 95% CI]": [
                "—"
                if x.input == "shuffled_generated"
                else fmt.with_ci(
                    x.margin_vs_shuffled, x.ci_low_vs_shuffled, x.ci_high_vs_shuffled, sign=True
                )
                for x in r.itertuples()
            ],
            "paper's Δ vs shuffled": [
                fmt.with_ci(*PAPER_MARGINS[x.attribute], sign=True)
                if x.input == "generated" and x.attribute in PAPER_MARGINS
                else "—"
                for x in r.itertuples()
            ],
            "majority word": r["majority"],
            "n train/test": [f"{x.n_train}/{x.n_test}" for x in r.itertuples()],
        }
    )


def language_sentences(rows: pd.DataFrame) -> list[str]:
    """Per corpus and attribute: does generated touch beat shuffled generated touch (the
    paper's evidence), and does real touch (what the adapter can read at best)?"""
    out = []
    for (corpus, attr), g in rows.groupby(["corpus", "attribute"], sort=True):
        by = g.set_index("input")
        gen, real = by.loc["generated"], by.loc["real"]
        out.append(
            f"{corpus}, {attr}: generated − shuffled "
            + claims.delta_verdict(
                gen["margin_vs_shuffled"],
                gen["ci_low_vs_shuffled"],
                gen["ci_high_vs_shuffled"],
                what="generated touch",
            )
            + f" Real touch reads {fmt.number(real['accuracy'])} against the majority word's "
            f"{fmt.number(real['majority'])}."
        )
    return out
