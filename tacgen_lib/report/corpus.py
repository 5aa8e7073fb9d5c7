"""Tables of the report's *Corpus* category built from a corpus edge (the figures are in
`figures`): the force bands against the true contact force."""

from __future__ import annotations

import pandas as pd

from tacgen_lib.corpus.force_bands import ForceBandCheck
from tacgen_lib.report import format as fmt

__all__ = ["force_band_table"]


def force_band_table(corpus: str, check: ForceBandCheck | None) -> pd.DataFrame:
    """One row per measure: the bands against each sample's own true force, beside the same
    measure against another sample's (the chance level). `check` None: nothing to check (a
    real corpus records no true force; a scene without press_jitter has no bands), said in the
    table."""
    if check is None:
        return pd.DataFrame(
            {
                "corpus": [corpus],
                "measure": [
                    "no band to check: no true contact force recorded (a real corpus), or one "
                    "press per sample (a scene without press_jitter)"
                ],
                "n": [0],
            }
        )
    cov = fmt.with_ci(check.coverage, check.coverage_low, check.coverage_high)
    shuffled = fmt.with_ci(check.shuffled_coverage, check.shuffled_low, check.shuffled_high)
    return pd.DataFrame(
        {
            "corpus": [corpus, corpus, corpus],
            "measure": [
                "R² of the band's p50 against the nominal press's force",
                "share of nominal forces inside [p05, p95] (Wilson 95 % CI)",
                "mean band width p95 − p05 (N)",
            ],
            "own force": [fmt.number(check.r2), cov, fmt.number(check.mean_width)],
            "another sample's force (control)": [
                fmt.number(check.shuffled_r2),
                shuffled,
                "—",
            ],
            "n": [check.n] * 3,
        }
    )
