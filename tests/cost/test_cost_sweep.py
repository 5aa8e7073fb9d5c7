"""Knob sweeps: the spread of replicate seeds, the Pareto front, the sentences and the marginal
table of the cost page (tacgen_lib.cost.spread, tacgen_lib.report.pareto), on hand-made numbers."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from tacgen_lib.cost.points import POINT_COLUMNS, check_points
from tacgen_lib.cost.spread import (
    replicate_seconds,
    retrieval_bootstrap,
    sd_interval,
    setting_seconds,
)
from tacgen_lib.cost.sweeps import (
    Seconds,
    align_points,
    backbone_points,
    bootstrap_spread_points,
    generate_points,
    permutation_points,
    point,
    policy_points,
)
from tacgen_lib.report.pareto import improvement, knob_sentence, marginal_table, pareto_front
from tacgen_lib.runtime.benchmarks import Benchmark


def points(knob, metric, rows, direction="higher"):
    """rows: (label, setting, is_default, value, ci_low, ci_high, wall_s); CPU = wall, 1 job."""
    return check_points(
        pd.DataFrame(
            [
                point(
                    knob,
                    "probes",
                    s,
                    lab,
                    d,
                    metric,
                    v,
                    (lo, hi),
                    "test",
                    Seconds(w, w, 1),
                    direction,
                )
                for lab, s, d, v, lo, hi, w in rows
            ]
        ),
        "hand",
    )


# ------------------------------------------------------------------------------ spread


def test_sd_interval_matches_the_chi_square_formula():
    values = [0.10, 0.12, 0.09, 0.11, 0.13]
    sd, lo, hi = sd_interval(values)
    assert sd == pytest.approx(np.std(values, ddof=1))
    assert lo == pytest.approx(sd * math.sqrt(4 / stats.chi2.ppf(0.975, 4)))
    assert hi == pytest.approx(sd * math.sqrt(4 / stats.chi2.ppf(0.025, 4)))
    assert lo < sd < hi


def test_sd_interval_of_one_run_is_nan_and_bad_confidence_raises():
    assert all(math.isnan(x) for x in sd_interval([0.3]))
    with pytest.raises(ValueError, match="confidence"):
        sd_interval([1.0, 2.0], confidence=1.5)


def test_sd_interval_covers_the_true_sd_about_95_percent_of_the_time():
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(2000):
        _, lo, hi = sd_interval(rng.normal(0.0, 2.0, 5))
        hits += lo <= 2.0 <= hi
    assert 0.93 <= hits / 2000 <= 0.97


def test_retrieval_bootstrap_figures_and_interval():
    ranks = np.array([[1, 1, 2, 5, 1, 3, 1, 8], [1, 2, 2, 4, 1, 1, 1, 9]])
    out = retrieval_bootstrap(ranks, 2000, seed=0)
    assert out["top1"] == pytest.approx(np.mean([4 / 8, 4 / 8]))
    assert out["median_rank"] == pytest.approx(np.mean([1.5, 1.5]))
    assert out["top1_low"] <= out["top1"] <= out["top1_high"]
    assert out["median_rank_low"] <= out["median_rank"] <= out["median_rank_high"]
    assert out["top1_high"] - out["top1_low"] > 0.1  # 8 test rows: a wide interval
    again = retrieval_bootstrap(ranks, 2000, seed=0)
    assert again == out  # reproducible from the seed


def test_retrieval_bootstrap_refuses_bad_ranks():
    with pytest.raises(ValueError, match="n_seeds, n_test"):
        retrieval_bootstrap(np.array([1, 2, 3]), 10, 0)
    with pytest.raises(ValueError, match=">= 1"):
        retrieval_bootstrap(np.array([[0, 2, 3]]), 10, 0)


def test_replicate_seconds_is_the_mean_of_one_run():
    wall, cpu, n = replicate_seconds([Benchmark(2.0, 1.0, 10), Benchmark(4.0, 3.0, 10)])
    assert (wall, cpu, n) == (3.0, 2.0, 2)
    with pytest.raises(ValueError, match="no benchmark"):
        replicate_seconds([])


def test_setting_seconds_sums_a_runs_jobs_and_averages_replicate_runs():
    nan = float("nan")
    one = setting_seconds([[Benchmark(2.0, 1.0, 10), Benchmark(4.0, 3.0, 20)]])
    assert one == Seconds(6.0, 4.0, 2)  # one run: its jobs add up
    reps = setting_seconds(
        [[Benchmark(2.0, 1.0, 10), Benchmark(4.0, nan, 5)], [Benchmark(8.0, 3.0, 1)]]
    )
    assert (reps.wall, reps.n_jobs) == (7.0, 3)  # the mean of the runs' sums: (6 + 8) / 2
    assert reps.cpu == 3.0  # a run whose CPU time is unknown drops out of the mean


# ------------------------------------------------------------------------------ points


def test_check_points_fills_and_checks_the_direction():
    p = points("k", "m", [("1", 1, True, 0.5, 0.4, 0.6, 1.0)])
    assert list(p.columns) == [*POINT_COLUMNS, "direction"]
    assert p["direction"].tolist() == ["higher"]
    bad = p.assign(direction="sideways")
    with pytest.raises(ValueError, match="direction"):
        check_points(bad, "hand")
    with pytest.raises(ValueError, match="outside"):
        check_points(p.assign(value=0.9), "hand")


# ------------------------------------------------------------------------------ pareto


def test_pareto_front_on_hand_data_both_directions():
    seconds = [1.0, 2.0, 3.0, 4.0, 2.5]
    values = [0.50, 0.70, 0.65, 0.80, 0.70]
    # higher is better: 3 s / 0.65 is dominated by 2 s / 0.70; 2.5 s / 0.70 by 2 s / 0.70
    assert pareto_front(seconds, values, "higher").tolist() == [True, True, False, True, False]
    # lower is better: only the cheapest point (0.50 at 1 s) is undominated
    assert pareto_front(seconds, values, "lower").tolist() == [True, False, False, False, False]


def test_pareto_front_keeps_ties_and_drops_nan():
    front = pareto_front([1.0, 1.0, 2.0, math.nan], [0.5, 0.5, 0.4, 0.9], "higher")
    assert front.tolist() == [True, True, False, False]
    with pytest.raises(ValueError, match="direction"):
        pareto_front([1.0], [1.0], "up")


def test_improvement_reads_the_direction():
    assert improvement(0.5, 0.7, "higher") == pytest.approx(0.2)
    assert improvement(5.0, 3.0, "lower") == pytest.approx(2.0)


def test_sentence_from_numbers_resamples():
    p = points(
        "probe_bootstrap",
        "sd of CI low across seeds",
        [
            ("200", 200, False, 0.020, 0.012, 0.057, 1.0),
            ("1,000", 1000, False, 0.008, 0.005, 0.023, 1.5),
            ("5,000", 5000, True, 0.004, 0.002, 0.011, 4.5),
        ],
        direction="lower",
    )
    text = knob_sentence(p, unit="resamples")
    # the default is the largest setting: compared with the next smaller one
    assert text.startswith("probe_bootstrap: from the default 5,000 resamples to 1,000 resamples")
    assert "worsens by 0.004 (0.004 → 0.008, inside the interval of 5,000 resamples)" in text
    assert "0.3× as long (4.5 s → 1.5 s)" in text
    assert "The default is on the Pareto front." in text
    # 0.008 lies inside the default's [0.002, 0.011]: 1,000 resamples is as good, measurably
    assert "1,000 resamples is within the default's uncertainty at 0.3× its time" in text
    no_default = knob_sentence(p.assign(is_default=False), unit="resamples")
    assert no_default.startswith("probe_bootstrap: from 200 resamples to 5,000 resamples, ")
    assert (
        "improves by 0.016 (0.020 → 0.004, outside the interval of 5,000 resamples)" in no_default
    )
    assert "22.5× as long" not in no_default and "4.5× as long (1 s → 4.5 s)" in no_default
    assert "Pareto" not in no_default


def test_sentence_names_a_cheaper_setting_inside_the_default_interval():
    p = points(
        "align_steps",
        "top-1",
        [
            ("300", 300, False, 0.30, 0.25, 0.35, 10.0),
            ("900", 900, True, 0.31, 0.26, 0.36, 30.0),
            ("2700", 2700, False, 0.33, 0.28, 0.38, 60.0),
        ],
    )
    text = knob_sentence(p, unit="steps")
    assert "from the default 900 steps to 2700 steps, top-1 improves by 0.02" in text
    assert "inside the interval of 2700 steps" in text  # the dearer setting's interval
    assert "2.0× as long (30 s → 60 s)" in text
    assert "300 steps is within the default's uncertainty at 0.3× its time" in text


def test_sentence_says_when_the_default_is_dominated():
    p = points(
        "w", "success", [("a", 1, True, 0.5, 0.4, 0.6, 5.0), ("b", 2, False, 0.7, 0.6, 0.8, 2.0)]
    )
    assert knob_sentence(p).endswith("The default is dominated.")
    with pytest.raises(ValueError, match="one knob"):
        knob_sentence(pd.concat([p, p.assign(metric="other")]))


def test_marginal_table_gain_per_minute_on_the_front():
    p = points(
        "k",
        "m",
        [
            ("a", 1, True, 0.50, 0.45, 0.55, 60.0),
            ("b", 2, False, 0.60, 0.55, 0.65, 120.0),
            ("c", 3, False, 0.55, 0.50, 0.60, 150.0),  # dominated: not on the front
            ("d", 4, False, 0.62, 0.57, 0.67, 300.0),
        ],
    )
    t = marginal_table(p)
    assert t[["from", "to"]].values.tolist() == [["a", "b"], ["b", "d"]]
    assert t["gain_per_min"].tolist() == pytest.approx([0.10, 0.02 / 3.0])
    assert t["within_uncertainty"].tolist() == [False, True]
    lower = marginal_table(p.assign(direction="lower"))
    assert lower.empty  # lower is better: the cheapest point dominates all


# ------------------------------------------------------------------------------ sweeps


SEC = {"a": Seconds(1.0, 0.5, 2), "b": Seconds(3.0, 2.0, 2)}


def test_align_points_carry_both_metrics_and_directions():
    ranks = {"a": [np.array([1, 2, 3, 1])], "all": [np.array([1, 1, 2, 1])]}
    p = check_points(
        align_points(
            "align_n",
            ranks,
            {"a": SEC["a"], "all": SEC["b"]},
            "all",
            n_resamples=200,
            seed=0,
            n_all=840,
        ),
        "align",
    )
    top1 = p[p["metric"].str.startswith("top-1")].set_index("label")
    assert top1.loc["all", "value"] == pytest.approx(0.75)
    assert top1.loc["all", "setting"] == 840 and bool(top1.loc["all", "is_default"])
    assert set(p.loc[p["metric"].str.startswith("median"), "direction"]) == {"lower"}


def test_spread_and_permutation_points():
    reps = pd.DataFrame(
        {
            "label": ["a"] * 3 + ["b"] * 3,
            "ci_low": [0.10, 0.12, 0.11, 0.110, 0.111, 0.112],
            "ci_high": [0.5, 0.52, 0.51, 0.51, 0.51, 0.51],
        }
    )
    p = check_points(bootstrap_spread_points("probe_bootstrap", reps, SEC, "b"), "boot")
    low = p[p["metric"].str.contains("lower")].set_index("label")["value"]
    assert low["a"] == pytest.approx(0.01) and low["b"] == pytest.approx(0.001)
    perm = pd.DataFrame({"label": ["a", "a"], "n_permutations": [9, 9], "delta_ctrl": [0.1, 0.3]})
    q = check_points(permutation_points("probe_permutations", perm, SEC, "a"), "perm")
    assert q.iloc[0]["value"] == pytest.approx(0.1) and math.isnan(q.iloc[0]["ci_low"])
    assert q.iloc[1]["value"] == pytest.approx(np.std([0.1, 0.3], ddof=1))


def test_generate_and_policy_points_average_seeds():
    cells = pd.DataFrame(
        {
            "label": ["a", "a"],
            "setting": [5, 5],
            "delta": [0.1, 0.2],
            "ci_low": [0.0, 0.1],
            "ci_high": [0.2, 0.3],
            "frechet": [4.0, 6.0],
        }
    )
    p = check_points(generate_points("generate_steps", cells, SEC, "a", target="force"), "gen")
    assert p.iloc[0][["value", "ci_low", "ci_high"]].tolist() == pytest.approx([0.15, 0.05, 0.25])
    assert p.iloc[1][["value", "ci_low", "ci_high"]].tolist() == pytest.approx([5.0, 4.0, 6.0])
    assert p.iloc[1]["direction"] == "lower"
    pol = pd.DataFrame(
        {
            "label": ["b"],
            "setting": [512],
            "success": [0.6],
            "ci_low": [0.5],
            "ci_high": [0.7],
            "n_episodes": [128],
        }
    )
    q = check_points(policy_points("policy_width", pol, SEC, "b"), "pol")
    assert bool(q.iloc[0]["is_default"]) and q.iloc[0]["wall_s"] == 3.0


def test_backbone_points_one_per_family_and_real_probe_under_the_linear_probe():
    def row(family, probe, protocol, null, delta):
        return {
            "family": family,
            "probe": probe,
            "protocol": protocol,
            "null_corpus": null,
            "status": "ok",
            "metric": "accuracy",
            "delta": delta,
            "ci_low": delta - 0.1,
            "ci_high": delta + 0.1,
        }

    rows = pd.DataFrame(
        [
            row("a", "hardness", "raw", False, 0.2),
            row("a", "hardness", "mlp2", False, 0.9),  # not the linear probe
            row("a", "hardness_null", "raw", True, 0.0),  # the control, not a point
            row("b", "hardness", "raw", False, 0.1),
        ]
    )
    p = check_points(backbone_points("backbones", rows, SEC, ["b", "a"], "a"), "bb")
    assert list(p["label"]) == ["b", "a"] and list(p["setting"]) == [0.0, 1.0]
    assert list(p["is_default"]) == [False, True]
    assert list(p["value"]) == [0.1, 0.2] and set(p["stage"]) == {"features"}
    assert list(p["wall_s"]) == [3.0, 1.0]  # each family's own seconds
