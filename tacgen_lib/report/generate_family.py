"""The Generation page's family-wise reading of its generated-touch rows.

Per corpus and target the page compares many rows of generated touch against V: V + T_gen and
its shuffled control in every sampling cell, and the ridge V->T generator's two arms, for every
generator seed (`generate.sampling_cells.family_size`). Read one by one at 95 %, about one in twenty of
them lies above 0 by chance where nothing is to be found (a null corpus); read together, by
their family-wise intervals (`generate.evaluate_probes.family_interval`: Bonferroni over the
family, Holm's first step), a row above 0 is a gain of the family. `family_table` counts both
readings per corpus and target and says whether the corpora where generated touch must not help
(the null corpus; density on the appearance-controlled corpus) show none.
"""

from __future__ import annotations

import pandas as pd

from tacgen_lib.report import format as fmt

__all__ = ["GENERATED_INPUTS", "family_rows", "family_table"]

#: The summary inputs that carry generated touch (the diffusion samples, their shuffled
#: control, the ridge V->T generator's arms).
GENERATED_INPUTS = ("t_gen", "t_gen_shuffled", "t_ridge", "t_ridge_residual")


def family_rows(summary: pd.DataFrame) -> pd.DataFrame:
    """The generated-touch rows of the summary, each compared once: the ridge arms, which
    every sampling cell of a generator repeats, once per seed."""
    g = summary[summary["input"].isin(GENERATED_INPUTS)]
    ridge = g["input"].str.startswith("t_ridge")
    once = g[ridge].drop_duplicates(["corpus", "target", "seed", "input"])
    return pd.concat([g[~ridge], once]).sort_values(["corpus", "target", "seed", "input"])


def _label(r: pd.Series) -> str:
    """A generated row in words: its input, its sampling cell (the ridge arms have none) and
    its generator seed."""
    if str(r["input"]).startswith("t_ridge"):
        return f"{r['input']}, seed {int(r['seed'])}"
    return (
        f"{r['input']} {r['sampler']} w = {r['guidance']:g}, {int(r['steps'])} steps, "
        f"seed {int(r['seed'])}"
    )


def _must_not_help(r: pd.Series) -> bool:
    """Where generated touch must not help: the null corpus, and the controlled corpus (its
    label, density, is invisible to V)."""
    return bool(r.get("null_corpus", False)) or r.get("design", "") == "controlled"


def family_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Per corpus x target: the generated-touch rows compared, how many have their 95 % CI
    above 0 and how many their family-wise interval, the row with the highest family-wise
    lower bound, and, where generated touch must not help, whether none of the family lies
    above 0."""
    out = []
    for (corpus, target), g in family_rows(summary).groupby(["corpus", "target"], sort=True):
        best = g.loc[g["ci_low_fw"].idxmax()] if g["ci_low_fw"].notna().any() else g.iloc[0]
        above_fw = int((g["ci_low_fw"] > 0).sum())
        must_not = _must_not_help(best)
        out.append(
            {
                "corpus": corpus,
                "target": target,
                "metric": g["metric"].iloc[0],
                "generated rows compared": len(g),
                "95 % CI above 0": int((g["ci_low"] > 0).sum()),
                "family-wise CI above 0": above_fw,
                "highest family-wise lower bound": f"{_label(best)}: "
                + fmt.with_ci(best["delta"], best["ci_low_fw"], best["ci_high_fw"], sign=True),
                "expected": "no gain (family-wise)" if must_not else "—",
                "as expected": ("yes" if above_fw == 0 else "NO") if must_not else "—",
            }
        )
    return pd.DataFrame(out)
