"""The Generation page's family-wise reading
(tacgen_lib.generate.evaluate_probes.family_interval, tacgen_lib.report.generate_family):
Bonferroni intervals over the generated-touch rows of one corpus and target, and the table that
counts them."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tacgen_lib.generate.evaluate_probes import FAMILY_ALPHA, family_interval
from tacgen_lib.generate.sampling_cells import family_size
from tacgen_lib.probes.bootstrap import percentile_interval
from tacgen_lib.report.generate_family import family_rows, family_table


def test_the_family_counts_both_inputs_per_cell_and_the_ridge_arms_per_seed():
    assert family_size(6, 1) == 14
    assert family_size(6, 3) == 42
    assert family_size(1, 1) == 4


def test_a_family_of_one_is_the_95_percent_ci_and_a_larger_one_is_wider():
    d = np.random.default_rng(0).normal(0.05, 0.03, 5000)
    assert family_interval(d, 1) == percentile_interval(d, confidence_level=0.95)
    lo1, hi1 = family_interval(d, 1)
    lo36, hi36 = family_interval(d, 36)
    assert lo36 < lo1 and hi36 > hi1
    # Bonferroni: the quantile at FAMILY_ALPHA / 2 / m each side
    assert lo36 == pytest.approx(np.quantile(d, FAMILY_ALPHA / 2 / 36))
    with pytest.raises(ValueError, match="at least 1"):
        family_interval(d, 0)


def test_on_a_null_family_chance_gains_vanish_family_wise():
    """36 comparisons of a difference with no effect: several 95 % CIs lie above 0 by
    chance in some draws; the family-wise intervals almost never do (FWER <= 5 %)."""
    rng = np.random.default_rng(1)
    above_95, above_fw = 0, 0
    draws = 200
    for _ in range(draws):
        # each comparison's bootstrap distribution about its own observed Δ, itself noise
        deltas = rng.normal(0.0, 1.0, size=(36, 1)) + rng.normal(0.0, 1.0, size=(36, 2000))
        above_95 += any(percentile_interval(d)[0] > 0 for d in deltas)
        above_fw += any(family_interval(d, 36)[0] > 0 for d in deltas)
    assert above_95 / draws > 0.5  # one CI of 36 above 0 is the rule, not the exception
    assert above_fw / draws <= 0.1


def _summary() -> pd.DataFrame:
    base = dict(target="hardness", metric="accuracy", sampler="ddim", steps=5, seed=0)
    rows = []
    for corpus, null, design in (("sim_null", True, "paired"), ("sim_paired", False, "paired")):
        for w, lo_fw in ((1.0, -0.02), (3.0, 0.01 if not null else -0.01)):
            for inp in ("t_gen", "t_gen_shuffled", "t_ridge", "t_ridge_residual"):
                rows.append(
                    {
                        **base,
                        "corpus": corpus,
                        "null_corpus": null,
                        "design": design,
                        "guidance": w,
                        "input": inp,
                        "delta": 0.05,
                        "ci_low": 0.01,  # every 95 % CI above 0
                        "ci_high": 0.09,
                        "ci_low_fw": lo_fw if inp == "t_gen" else -0.03,
                        "ci_high_fw": 0.12,
                    }
                )
        rows.append({**base, "corpus": corpus, "null_corpus": null, "design": design,
                     "guidance": 1.0, "input": "t_real", "delta": 0.2, "ci_low": 0.1,
                     "ci_high": 0.3, "ci_low_fw": np.nan, "ci_high_fw": np.nan})  # fmt: skip
    return pd.DataFrame(rows)


def test_the_family_table_reads_each_generated_row_once():
    s = _summary()
    # the ridge arms repeat in each of the 2 cells: counted once per seed; real touch not at all
    assert len(family_rows(s[s["corpus"] == "sim_null"])) == 2 * 2 + 2
    table = family_table(s).set_index("corpus")
    null, paired = table.loc["sim_null"], table.loc["sim_paired"]
    assert null["generated rows compared"] == 6 and null["95 % CI above 0"] == 6
    assert null["family-wise CI above 0"] == 0 and null["as expected"] == "yes"
    assert paired["family-wise CI above 0"] == 1 and paired["as expected"] == "—"
    assert paired["highest family-wise lower bound"].startswith("t_gen ddim w = 3, 5 steps, seed 0")
    flipped = s.copy()
    flipped.loc[
        (flipped["corpus"] == "sim_null") & (flipped["input"] == "t_ridge"), "ci_low_fw"
    ] = 0.02
    row = family_table(flipped).set_index("corpus").loc["sim_null"]
    assert row["as expected"] == "NO" and row["highest family-wise lower bound"].startswith(
        "t_ridge, seed 0"
    )
