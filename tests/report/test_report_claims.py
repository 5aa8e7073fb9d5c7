"""The report's words and numbers: one formatter (tacgen_lib.report.format), one function per
claim (tacgen_lib.report.claims), the findings page built from them, and the figure check that
keeps every figure readable in the viewer. Edge cases: a tie, a CI touching 0, a single point,
a degenerate interval, values that round to zero."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.stats import binomtest

from tacgen_lib.policy import oracle
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.report import claims, findings
from tacgen_lib.report import format as fmt
from tacgen_lib.report.pareto import knob_sentence, marginal_table
from tacgen_lib.report.tables import cell_html, constants_to_lead, footnote_column, to_html
from tacgen_lib.report.write import MAX_FIGURE_PX, figure_problems, panel_grid, write_figure
from tacgen_lib.report_pages import PAGES, category, page_of

# ----------------------------------------------------------------------------- format


def test_numbers_have_three_decimals_and_no_negative_zero():
    assert fmt.number(0.123456) == "0.123"
    assert fmt.number(-0.0004) == "0.000"  # rounds to zero: no "-0.000"
    assert fmt.signed(-0.0004) == "+0.000"
    assert fmt.signed(0.0123) == "+0.012" and fmt.signed(-0.03) == "-0.030"
    assert fmt.number(16) == "16" and fmt.number(np.int64(16)) == "16"
    assert fmt.number(math.nan) == fmt.MISSING and fmt.number(None) == fmt.MISSING
    assert fmt.number(pd.NA) == fmt.MISSING
    assert fmt.number(math.inf) == "∞"


def test_a_value_without_an_interval_says_why():
    assert fmt.with_ci(0.5, 0.4, 0.6) == "0.500 [0.400, 0.600]"
    assert fmt.with_ci(0.05, -0.01, 0.1, sign=True) == "+0.050 [-0.010, +0.100]"
    assert fmt.with_ci(0.05, math.nan, math.nan, sign=True) == "+0.050 (no interval: one point)"
    assert fmt.with_ci(math.nan, 0.0, 1.0) == fmt.MISSING


def test_count_columns_are_integers_and_score_columns_stay_scores():
    counts = pd.Series([16.0, 8.0, math.nan])
    assert fmt.column_cells(counts) == ["16", "8", fmt.MISSING]
    scores = pd.Series([1.0, 0.0, 1.0])  # 0/1 scores stay scores
    assert fmt.column_cells(scores) == ["1.000", "0.000", "1.000"]
    assert fmt.column_cells(pd.Series([True, False])) == ["yes", "no"]


def test_class_labels_sort_by_value():
    assert fmt.numeric_order(["2000.0", "500.0", "5000.0"]) == ["500.0", "2000.0", "5000.0"]
    assert fmt.numeric_order([5000, 500, 2000]) == [500, 2000, 5000]
    assert fmt.numeric_order(["soft", "hard"]) == ["hard", "soft"]


def test_tables_write_no_nan_and_footnote_the_dash():
    table = pd.DataFrame({"rows": [16.0, math.nan], "Δ": [-0.0001, 0.25], "score": [0.5, 0.12345]})
    page = to_html(table, title="t", missing="not run for this row")
    assert "nan" not in page.lower().replace("name", "")
    assert ">16<" in page and "16.0" not in page
    assert "+0.000" in page and "-0.000" not in page and "+0.250" in page
    assert f"{fmt.MISSING}: not run for this row." in page
    assert "0.123" in page and "0.12345" not in page
    # a lead paragraph comes before the table, a note after it
    page = to_html(table, title="t", lead=["What it says."], notes=["How it was made."])
    assert page.index("What it says.") < page.index("<table>") < page.index("How it was made.")


def test_long_identifiers_break_between_their_parts_and_words_never():
    # a long identifier gets a break opportunity after each separator; short ones, plain
    # words and the text a reader copies stay as they are
    got = cell_html("sim_natural_r05|32|1024 at N_L = 8, x<y")
    assert got == "sim_<wbr>natural_<wbr>r05|<wbr>32|<wbr>1024 at N_L = 8, x&lt;y"
    assert cell_html("Δ_ctrl hardness") == "Δ_ctrl hardness"
    assert cell_html("a_very_long_identifier").replace("<wbr>", "") == "a_very_long_identifier"
    page = to_html(pd.DataFrame({"N_L": [8], "cell": ["sim_natural_r05|32"]}), title="t")
    assert "<th>N_L</th>" in page and "sim_<wbr>natural_<wbr>r05|<wbr>32" in page


def test_a_column_of_sentences_becomes_footnote_marks():
    table = pd.DataFrame({"x": [1, 2, 3, 4], "notes": ["too wide", "", "too wide", "one class"]})
    marked, notes = footnote_column(table, "notes")
    assert list(marked["notes"]) == ["[1]", "", "[1]", "[2]"]
    assert notes == ["[1] too wide", "[2] one class"]
    assert list(table["notes"])[0] == "too wide"  # the input is not changed


def test_columns_every_row_shares_move_above_the_table():
    table = pd.DataFrame({"seed": [42, 42], "metric": ["r2", "accuracy"], "v": [0.1, 0.2]})
    rest, lead = constants_to_lead(table, ("seed", "metric", "absent"))
    assert list(rest.columns) == ["metric", "v"] and lead == ["Every row: seed 42."]
    # one row, or nothing shared: the table keeps every column
    one, lead = constants_to_lead(table.head(1), ("seed",))
    assert one.equals(table.head(1)) and lead == []
    assert constants_to_lead(table, ("metric",))[1] == []


@given(st.floats(allow_nan=True, allow_infinity=True, width=64))
def test_every_real_formats_without_nan_or_negative_zero(x):
    for text in (fmt.number(x), fmt.signed(x), fmt.cell(x)):
        assert "nan" not in text and text != "-0.000"


# ----------------------------------------------------------------------------- claims


@pytest.mark.parametrize(
    ("lo", "hi", "side", "words"),
    [
        (0.01, 0.2, "above", "helps"),
        (-0.2, -0.01, "below", "hurts"),
        (0.0, 0.2, "touches", "touches 0"),  # a CI touching 0 does not exclude it
        (-0.2, 0.0, "touches", "touches 0"),
        (-0.1, 0.1, "spans", "contains 0"),
        (0.0, 0.0, "touches", "touches 0"),  # a tie
        (math.nan, math.nan, "none", "no interval"),  # a single point
    ],
)
def test_delta_verdict_reads_the_interval(lo, hi, side, words):
    assert claims.interval_side(lo, hi) == side
    assert words in claims.delta_verdict(0.05 if side != "below" else -0.05, lo, hi)


def test_probe_verdict_reads_the_controls_and_the_null_corpus():
    met = claims.probe_verdict(
        0.3, 0.2, 0.4, null_corpus=False, criterion_met=True, delta_ctrl=0.01
    )
    assert "criterion met" in met and "helps" in met
    not_met = claims.probe_verdict(
        0.3, 0.2, 0.4, null_corpus=False, criterion_met=False, delta_ctrl=0.35
    )
    assert "criterion not met" in not_met
    null_ok = claims.probe_verdict(
        0.01, -0.05, 0.07, null_corpus=True, criterion_met=False, delta_ctrl=0.0
    )
    assert null_ok.startswith("As expected on the null corpus")
    null_bad = claims.probe_verdict(
        0.2, 0.1, 0.3, null_corpus=True, criterion_met=True, delta_ctrl=0.0
    )
    assert null_bad.startswith("UNEXPECTED")


def test_generation_verdict_credits_the_probe_when_a_nonlinear_v_gains_as_much():
    text = claims.generation_verdict((0.1, 0.05, 0.15), (0.3, 0.2, 0.4), (0.12, 0.06, 0.18))
    assert text.startswith("Generated touch helps") and "gain is in the probe" in text
    text = claims.generation_verdict((0.0, -0.05, 0.05), (0.3, 0.2, 0.4), (0.0, 0.0, 0.0))
    assert text.startswith("Generated touch does not help") and "real touch does" in text
    one_seed = claims.generation_verdict((0.1, math.nan, math.nan), (0.3, 0.2, 0.4), (0, 0, 0))
    assert one_seed.startswith("Generated touch does not help") and "one point" in one_seed


def test_ridge_verdict_reads_the_probe_interval_and_the_pairing_gaps():
    def pairing(gen, mean, residual):  # matched-pair cosines, off-diagonal 0.1 each
        return {"t_gen": (gen, 0.1), "t_ridge": (mean, 0.1), "t_ridge_residual": (residual, 0.1)}

    below = claims.ridge_verdict((-0.1, -0.2, -0.01), pairing(0.33, 0.68, 0.41), 0.001)
    assert below.startswith("V + T_gen scores below V + ridge V→T") and "cost the probe" in below
    assert "+0.230, against +0.580" in below and "+0.310 for ridge + a sampled residual" in below
    assert "learnt less of the V→T map than a linear regression" in below
    between = claims.ridge_verdict((0.1, 0.01, 0.2), pairing(0.55, 0.7, 0.45), 0.001)
    assert between.startswith("V + T_gen beats V + ridge V→T") and "not its mean" in between
    best = claims.ridge_verdict((0.0, -0.1, 0.1), pairing(0.72, 0.7, 0.45), 0.001)
    assert "better than ridge's mean" in best
    # with the gaps' paired intervals over the test rows, those decide: a point above ridge's
    # mean whose interval holds 0 is paired as ridge's samples are
    gaps = {"ridge": (0.02, -0.03, 0.07), "ridge_residual": (0.27, 0.2, 0.33)}
    as_ridge = claims.ridge_verdict((0.0, -0.1, 0.1), pairing(0.72, 0.7, 0.45), 0.001, gaps)
    assert "as ridge's are, within the test rows' uncertainty" in as_ridge
    assert "− ridge's mean +0.020 [-0.030, +0.070]" in as_ridge
    less = {"ridge": (-0.2, -0.3, -0.1), "ridge_residual": (-0.1, -0.15, -0.05)}
    assert claims.pairing_decision({}, 0.001, less) == "less paired than ridge's samples"
    between = {"ridge": (-0.2, -0.3, -0.1), "ridge_residual": (0.1, 0.05, 0.15)}
    assert (
        claims.pairing_decision({}, 0.01, between) == "paired between ridge's samples and its mean"
    )
    assert claims.pairing_decision({}, 0.2, less) == "not measurably paired"
    # a null corpus: matched = off-diagonal, the permutation p large -> not paired, whatever
    # the cosines' sizes
    null = claims.ridge_verdict(
        (0.0, -0.1, 0.1),
        {"t_gen": (0.149, 0.147), "t_ridge": (-0.03, -0.05), "t_ridge_residual": (0.11, 0.11)},
        0.48,
    )
    assert "not measurably paired with the real rows (pairing p 0.480" in null
    for lo in (-0.1, 0.0):  # an interval containing or touching 0 favours neither
        text = claims.ridge_verdict((0.0, lo, 0.1), pairing(0.5, 0.6, 0.4), 0.001)
        assert text.startswith("In the probe V + T_gen and V + ridge V→T do not differ")
    one_point = claims.ridge_verdict((0.1, math.nan, math.nan), pairing(0.5, 0.6, 0.4), 0.001)
    assert one_point.startswith("In the probe V + T_gen and V + ridge V→T do not differ")


def test_ceiling_verdict_never_calls_a_point_above_the_ceiling_a_breach_unless_its_ci_is():
    assert "below the vision-only ceiling" in claims.ceiling_verdict(0.3, 0.22, 0.36, 0.383)
    noise = claims.ceiling_verdict(0.430, 0.352, 0.516, 0.383)
    assert "sampling noise" in noise and "UNEXPECTED" not in noise
    assert claims.ceiling_verdict(0.6, 0.5, 0.7, 0.383).startswith("UNEXPECTED")
    assert "within its interval" in claims.ceiling_verdict(0.36, 0.3, 0.4, 0.383)


@pytest.mark.parametrize(("k", "n"), [(0, 10), (10, 10), (128, 128), (55, 128), (1, 1)])
def test_wilson_interval_matches_scipy(k, n):
    lo, hi = claims.proportion_interval(k, n)
    ref = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    # scipy's z comes from its own normal quantile: equal within float rounding
    np.testing.assert_allclose([lo, hi], [ref.low, ref.high], rtol=1e-9, atol=1e-12)
    assert hi > lo  # never degenerate, unlike a bootstrap of all-successes


def test_extreme_values_are_flagged_with_their_reason():
    assert "below −1" in claims.extreme_flag("r2", -28.3, 0.5, -3.0, 1.0)
    assert "beyond ±1" in claims.extreme_flag("r2", -0.87, 0.94, 1.35, 2.51)
    assert "majority-class" in claims.extreme_flag("accuracy", 0.43, 0.73, 0.2, 0.4, 0.5)
    assert claims.extreme_flag("r2", 0.4, 0.9, 0.42, 0.61) == ""


def test_still_falling_reads_the_end_of_a_curve():
    steps = np.arange(0, 501, 50)
    assert claims.still_falling(steps, 1.0 / (1 + steps / 50))  # still dropping fast
    assert not claims.still_falling(steps, 0.5 + np.exp(-steps / 20))  # flat at the end
    assert not claims.still_falling([0, 1], [1.0, 0.5])  # too short to say


# the cost page: the knob sentence and the marginal table use one test ("within uncertainty")
def _points(rows):
    cols = ["label", "setting", "is_default", "value", "ci_low", "ci_high", "wall_s"]
    p = pd.DataFrame(rows, columns=cols)
    return p.assign(knob="steps", metric="Δ", direction="higher")


@pytest.mark.parametrize(
    "rows",
    [
        # the cheaper 5-step value inside the dearer default's interval, not the reverse
        [("5", 5, False, 0.10, 0.02, 0.18, 60.0), ("25", 25, True, 0.14, 0.08, 0.20, 200.0)],
        # the reverse: the dearer value inside the cheaper point's wide interval only
        [("5", 5, False, 0.10, 0.00, 0.30, 60.0), ("25", 25, True, 0.25, 0.22, 0.28, 200.0)],
    ],
)
def test_cost_sentence_and_marginal_table_agree(rows):
    p = _points(rows)
    sentence = knob_sentence(p)
    marginal = marginal_table(p)
    within = bool(marginal["within_uncertainty"].iloc[0])
    cheap, dear = p.iloc[0], p.iloc[1]
    assert within == claims.gain_within_uncertainty(cheap["value"], dear["ci_low"], dear["ci_high"])
    assert ("inside the interval of 25" in sentence) == within
    assert ("is within the default's uncertainty" in sentence) == within


# ----------------------------------------------------------------------------- ceiling


def test_vision_ceiling_is_the_expected_success_of_the_best_force_given_size():
    s = PolicySettings(ceiling_draws=600)
    c = oracle.vision_ceiling_success(s, seed=5, n_sizes=24)
    assert 0.0 < c < 1.0
    assert c == oracle.vision_ceiling_success(s, seed=5, n_sizes=24)  # same computation twice
    # the best force given the size beats any single force for every size, so in expectation
    # the ceiling beats the policy that grips every object with one force
    sizes = np.linspace(*s.size_range, 24)
    one_force = oracle.vision_ceiling_force(s, float(np.mean(s.size_range)), seed=5)
    p_one = []
    for size in sizes:
        lo, hi = oracle.invisible_prior(s, float(size), s.ceiling_draws, seed=5)
        p_one.append(np.mean((lo <= one_force) & (one_force <= hi)))
    assert c >= float(np.mean(p_one)) - 0.05


# ----------------------------------------------------------------------------- findings


def _probe_summary():
    base = dict(
        control="none",
        fusion="concat",
        t_variant="clip128",
        heads_variant="clip128",
        status="ok",
        corpus="sim_paired",
        metric="accuracy",
        align_seed=math.nan,
        probe_seed=42,
        input="raw",
    )
    return pd.DataFrame(
        [
            {
                **base,
                "family": "hardness",
                "target": "hardness",
                "null_corpus": False,
                "v_score": 0.45,
                "vt_score": 0.75,
                "delta": 0.30,
                "ci_low": 0.22,
                "ci_high": 0.37,
                "delta_ctrl": 0.01,
                "criterion_met": True,
            },
            {
                **base,
                "family": "hardness_null",
                "target": "hardness",
                "null_corpus": True,
                "corpus": "sim_null",
                "v_score": 0.48,
                "vt_score": 0.49,
                "delta": 0.01,
                "ci_low": -0.05,
                "ci_high": 0.07,
                "delta_ctrl": 0.01,
                "criterion_met": False,
            },
            # no controls run on this one: not a finding
            {
                **base,
                "family": "hardness",
                "target": "hardness",
                "null_corpus": False,
                "fusion": "max",
                "v_score": 0.45,
                "vt_score": 0.7,
                "delta": 0.25,
                "ci_low": 0.2,
                "ci_high": 0.3,
                "delta_ctrl": math.nan,
                "criterion_met": None,
            },
        ]
    )


def test_findings_rows_carry_result_control_verdict_and_page():
    rows, decided = findings.probe_findings(_probe_summary())
    assert list(rows.columns) == findings.FINDINGS_COLUMNS
    assert len(rows) == 2  # one per family with its controls; the max fusion is not a finding
    main = rows.iloc[0]
    assert "Δ +0.300 [+0.220, +0.370]" in main["result"]
    assert "criterion met" in main["verdict"] and main["page"] == category("Probes")
    assert rows.iloc[1]["verdict"].startswith("As expected on the null corpus")
    # every verdict's decisions, keyed by what they decide
    by_id = {d["decision_id"]: d for d in decided}
    assert by_id["probe|hardness|raw"]["decision"] == "above 0"
    assert by_id["probe|hardness|raw|criterion"]["decision"] == "met"
    assert by_id["probe|hardness_null|raw"]["decision"] == "no measurable difference"


def test_aligned_findings_read_every_heads_seed():
    """Heads trained with two seeds: a gain one seed's heads show and the other's do not is
    no measurable difference, and one the seeds agree on is read from both intervals."""
    base = _probe_summary().iloc[0].to_dict()

    def aligned(seed, delta, lo, hi, ctrl=0.01):
        return {
            **base,
            "input": "aligned",
            "align_seed": seed,
            "delta": delta,
            "ci_low": lo,
            "ci_high": hi,
            "delta_ctrl": ctrl,
        }

    disagree = pd.DataFrame(
        [aligned(42, 0.13, -0.25, 0.49), aligned(43, 0.59, 0.39, 0.78, math.nan)]
    )
    rows, decided = findings.probe_findings(disagree)
    assert len(rows) == 1 and "per seed 42: +0.130" in rows.iloc[0]["result"]
    (d,) = [d for d in decided if d["decision_id"] == "probe|hardness|aligned"]
    assert d["decision"] == "no measurable difference" and d["ci_low"] == -0.25
    assert d["value"] == pytest.approx(0.36)
    # both seeds' heads help, by other amounts: above 0, whatever their spread
    agree = pd.DataFrame([aligned(42, 0.83, 0.76, 0.89), aligned(43, 0.70, 0.63, 0.78, math.nan)])
    _, decided = findings.probe_findings(agree)
    (d,) = [d for d in decided if d["decision_id"] == "probe|hardness|aligned"]
    assert d["decision"] == "above 0" and (d["ci_low"], d["ci_high"]) == (0.63, 0.89)


def test_seeds_interval_holds_each_replicate_and_from_three_their_spread():
    assert claims.seeds_interval([0.2], [0.1], [0.3]) == (0.2, 0.1, 0.3)
    # two replicates: their intervals alone (a t-interval of one degree of freedom is noise)
    m, lo, hi = claims.seeds_interval([0.83, 0.70, np.nan], [0.76, 0.63, 0.0], [0.89, 0.78, 0.0])
    assert m == pytest.approx(0.765) and (lo, hi) == (0.63, 0.89)
    # three: each interval and the mean's t-interval over them
    d, lo3, hi3 = [0.01, 0.011, 0.03], [0.001, 0.002, 0.02], [0.02, 0.02, 0.04]
    m, lo, hi = claims.seeds_interval(d, lo3, hi3)
    _, t_lo, t_hi = claims.mean_t_interval(d)
    assert t_lo < 0 < min(lo3) and (lo, hi) == (t_lo, max(t_hi, 0.04))
    assert all(math.isnan(x) for x in claims.seeds_interval([np.nan], [0.0], [1.0]))


def test_below_majority_needs_the_wilson_interval_below_it():
    # 114 of 240 right (0.475) against a majority of 0.52: within the test rows' noise
    assert not claims.below_majority(0.475, 0.52, 240)
    assert claims.below_majority(0.40, 0.52, 240)
    assert claims.below_majority(0.475, 0.52)  # no row count: the point decides
    assert not claims.below_majority(math.nan, 0.52, 240)


def test_policy_findings_use_the_ceiling_claim():
    summary = pd.DataFrame(
        [
            {"condition": "v", "success": 0.43, "ci_low": 0.35, "ci_high": 0.52, "n_episodes": 128},
            {
                "condition": "vt_aligned",
                "success": 1.0,
                "ci_low": 1.0,
                "ci_high": 1.0,
                "n_episodes": 128,
            },
        ]
    )
    deltas = pd.DataFrame(
        [
            {
                "condition": "vt_aligned",
                "delta": 0.57,
                "ci_low": 0.48,
                "ci_high": 0.65,
                "n_episodes": 128,
            },
            {
                "condition": "vt_null",
                "delta": -0.07,
                "ci_low": -0.16,
                "ci_high": 0.02,
                "n_episodes": 128,
            },
        ]
    )
    sweep = pd.DataFrame(
        {"success": [0.38, 0.44], "gap_closed": [-0.09, 0.02], "vision_ceiling": [0.363, 0.363]}
    )
    rows, decided = findings.policy_findings(summary, deltas, sweep)
    assert [d["decision"] for d in decided] == ["above 0", "reaches the ceiling"]
    assert rows["verdict"].iloc[0].startswith("Touch helps")
    # all 128 successes: the Wilson interval, not a bootstrap of width 0
    assert "V+T 1.000 [0.971, 1.000] (Wilson: all 128/128 alike)" in rows["result"].iloc[0]
    assert rows["verdict"].iloc[1] == claims.ceiling_verdict(0.43, 0.35, 0.52, 0.363)
    assert (
        "best of the capacity sweep 0.440, closing +0.020 of the V → V+T gap"
        in rows["result"].iloc[1]
    )


# ----------------------------------------------------------------------------- pages, figures


def test_pages_are_numbered_in_the_papers_order():
    names = [category(p) for p in PAGES]
    assert names == sorted(names)  # the viewer's text sort keeps the paper's order
    assert names[0] == "01 Findings" and page_of("06 Probes") == "Probes"
    with pytest.raises(KeyError, match="not one of"):
        category("Results")


def test_a_figure_the_viewer_cannot_show_is_refused(tmp_path):
    fig, ax = plt.subplots(figsize=(14, 4))
    ax.set_title("too wide", fontsize=10)
    assert "larger than the viewer" in figure_problems(fig)[0]
    with pytest.raises(ValueError, match="wide.png: figure not readable"):
        write_figure(fig, tmp_path / "wide.png")
    assert not (tmp_path / "wide.png").exists()  # nothing half-written
    fig, ax = plt.subplots(figsize=(5, 3))
    ax.text(0.5, 0.5, "tiny", fontsize=5)
    assert "text below 8 pt" in figure_problems(fig)[0]
    plt.close(fig)


@given(st.integers(1, 12), st.floats(2.0, 6.0), st.floats(1.8, 4.0))
def test_panel_grid_fits_the_viewer_or_says_to_split(n, w, h):
    try:
        nrows, ncols, (fw, fh) = panel_grid(n, (w, h))
    except ValueError as err:
        assert "split them" in str(err)
        return
    assert nrows * ncols >= n
    assert fw * 110 <= MAX_FIGURE_PX[0] + 1e-6 and fh * 110 <= MAX_FIGURE_PX[1] + 1e-6


# the Probes page's fusion table says what the plan does: same-dimension fusions run on raw
# features where V and T have equal size (the forest plot then shows raw/max rows), and are
# skipped, with the reason, where they do not
def test_fusion_table_states_the_planning_rule():
    from tacgen_lib.probes.fusion import FUSIONS
    from tacgen_lib.probes.plan import plan_comparisons

    def raw(dim_t):
        plan = plan_comparisons(
            list(FUSIONS),
            heads_variant="clip128",
            variants=["clip128"],
            align_seeds=[42],
            dim_v_raw=192,
            dim_t_raw=dim_t,
        )
        return {s.fusion: s.skip_reason for s in plan if s.input == "raw"}

    equal, unequal = raw(192), raw(384)
    for name, f in FUSIONS.items():
        if f.same_dim:
            assert equal[name] is None and unequal[name] is not None
            assert "raw of equal size" in f.inputs  # what the table says, what the plan does
        else:
            assert equal[name] is None and unequal[name] is None


def test_generation_verdict_reads_right_in_all_four_cases():
    up, flat = (0.1, 0.05, 0.15), (0.0, -0.05, 0.05)
    none = (0.0, 0.0, 0.0)
    assert "so does real touch" in claims.generation_verdict(up, up, none)
    assert "; real touch does (" in claims.generation_verdict(flat, up, none)
    both_flat = claims.generation_verdict(flat, flat, none)
    assert (
        both_flat.startswith("Generated touch does not help") and "nor does real touch" in both_flat
    )
    # a gain from generated touch where real touch gives none is flagged, not credited
    odd = claims.generation_verdict(up, flat, none)
    assert odd.startswith("Generated touch helps") and "real touch does not" in odd
    assert "not touch's information" in odd and "nor" not in odd
