"""The page *Where generated touch helps*: its hypotheses (H1-H5 and the pool without
generation), each tested on the replicate summary (`tacgen_lib.report.regime.seed_view`) and
stated as measured, and how a row's replicates are put in words (`replicate_words`).
"""

from __future__ import annotations

import pandas as pd

from tacgen_lib.report import format as fmt
from tacgen_lib.report.regime_arms import ARM_LABELS, NOT_BUILT_ON_V, arm_rows

__all__ = ["hypothesis_sentences", "replicate_words"]


def replicate_words(r: pd.Series, what: str) -> str:
    """A `seed_view` row's mean Delta against `what` (linear_v | nonlinear_v | distilled) with
    the replicates' interval read as one (what a gain is decided on, `regime_arms.gains`) and how many
    replicates' CIs lie above or below 0, in words."""
    d, n = r[f"delta_vs_{what}"], int(r["n_seeds"])
    rep = f"[{fmt.signed(r[f'rep_low_vs_{what}'])}, {fmt.signed(r[f'rep_high_vs_{what}'])}]"
    up, down = int(r[f"above_vs_{what}"]), int(r[f"below_vs_{what}"])
    if up:
        side = f"CI above 0 in {up} of {n} replicates"
    elif down:
        side = f"CI below 0 in {down} of {n} replicates"
    else:
        side = f"CI includes 0 in each of {n} replicates"
    return f"{fmt.signed(d)} {rep} ({side})"


def hypothesis_sentences(view: pd.DataFrame) -> list[str]:
    """The issue's four expectations, each tested on the numbers and stated as measured: H1 at
    the smallest rho, H2 and the pool without generation at the largest rho with the fewest
    labels and the largest pool, H3 as the labels grow, H4 and H5 against the two ceilings."""
    rhos = sorted(view["rho"].unique())
    ls = sorted(view["n_labelled"].unique())
    n_p = view["n_pool"].max()
    built_on_v = view[~view["arm"].isin(NOT_BUILT_ON_V)]
    top = view[(view["rho"] == rhos[-1]) & (view["n_labelled"] == ls[0]) & (view["n_pool"] == n_p)]
    return [
        _h1_no_arm_beats_v_without_correlation(built_on_v, rhos[0]),
        *_h2_generated_touch_beats_linear_v(top, rhos[-1], ls[0], n_p),
        *_h3_gain_shrinks_with_labels(view, rhos[-1], ls, n_p),
        *_pool_without_generation(top, rhos[-1], ls[0], n_p),
        _h4_below_vision_ceiling(view, built_on_v),
        _h5_below_v_ceiling(view, built_on_v),
    ]


def _h1_no_arm_beats_v_without_correlation(built_on_v: pd.DataFrame, rho: float) -> str:
    """H1: at rho = 0 every arm built on V matches nonlinear V."""
    r0 = built_on_v[
        (built_on_v["rho"] == rho)
        & ~((built_on_v["arm"] == "v") & (built_on_v["probe"] == "nonlinear"))
    ]
    off = r0[
        (r0["above_vs_nonlinear_v"] == r0["n_seeds"])
        | (r0["below_vs_nonlinear_v"] == r0["n_seeds"])
    ]
    above = int((off["above_vs_nonlinear_v"] == off["n_seeds"]).sum())
    return (
        f"H1 (ρ = {rho:g}: no arm built on V beats nonlinear V): {above} of {len(r0)} "
        f"arm × cell rows beat it with the CI above 0 in every replicate; "
        f"{len(off) - above} fall below it in every replicate."
    )


def _h2_generated_touch_beats_linear_v(
    top: pd.DataFrame, rho: float, n_l: int, n_p: int
) -> list[str]:
    """H2: at the largest rho, the fewest labels and the largest pool, V + T_gen beats linear V
    (one sentence per probe that has the arm)."""
    out = []
    for probe in ("linear", "nonlinear"):
        g = arm_rows(top, "v_tgen", probe)
        if g.empty:
            continue
        r = g.iloc[0]
        out.append(
            f"H2 (ρ = {rho:g}, N_L = {n_l}, N_P = {n_p}: V + T_gen beats linear V), "
            f"{probe} probe: Δ vs linear V "
            f"{replicate_words(r, 'linear_v')}"
            f"; vs nonlinear V "
            f"{replicate_words(r, 'nonlinear_v')}"
            f"; vs distillation "
            f"{replicate_words(r, 'distilled')}."
        )
    return out


def _h3_gain_shrinks_with_labels(view: pd.DataFrame, rho: float, ls: list, n_p: int) -> list[str]:
    """H3: the gain of V + T_gen over linear V shrinks as N_L grows (one sentence per target;
    untestable where there is no gain at the fewest labels)."""
    out = []
    g = arm_rows(view[(view["rho"] == rho) & (view["n_pool"] == n_p)], "v_tgen", "linear")
    for target, t in g.groupby("target", sort=True):
        t = t.sort_values("n_labelled")
        d = t["delta_vs_linear_v"].to_numpy()
        if d[0] <= 0:
            verdict = (
                f"untestable: there is no gain at N_L = {ls[0]} to shrink "
                f"({fmt.signed(d[0])}; {fmt.signed(d[-1])} at N_L = {ls[-1]})"
            )
        else:
            trend = "shrinks" if d[-1] < d[0] else "does not shrink"
            verdict = (
                f"the Δ of V + T_gen over linear V {trend} from {fmt.signed(d[0])} at N_L = "
                f"{ls[0]} to {fmt.signed(d[-1])} at N_L = {ls[-1]}"
            )
        out.append(f"H3 ({target}, ρ = {rho:g}, N_P = {n_p}): {verdict}.")
    return out


def _pool_without_generation(top: pd.DataFrame, rho: float, n_l: int, n_p: int) -> list[str]:
    """The pool without generation: distillation against linear V, and V + T_gen against
    distillation (one sentence per target)."""
    out = []
    for target, t in top.groupby("target", sort=True):
        d = arm_rows(t, "distilled", "linear").iloc[0]
        gen = arm_rows(t, "v_tgen", "linear").iloc[0]
        pool_only = gen["above_vs_distilled"] < gen["n_seeds"]
        out.append(
            f"The pool without generation ({target}, ρ = {rho:g}, N_L = {n_l}, N_P = "
            f"{n_p}): generalised distillation (linear student on V) vs linear V "
            f"{replicate_words(d, 'linear_v')}"
            f"; V + T_gen vs distillation "
            f"{replicate_words(gen, 'distilled')}"
            + (
                ": generation adds nothing the pool does not give without it."
                if pool_only
                else ": generation beats the V-only use of the pool in every replicate."
            )
        )
    return out


#: the cell a ceiling row is read at: every arm of a cell is compared with the ceilings of that cell
_CEILING_KEY = ["corpus", "rho", "n_labelled", "n_pool", "target"]


def _h4_below_vision_ceiling(view: pd.DataFrame, built_on_v: pd.DataFrame) -> str:
    """H4: no arm built on V exceeds the vision ceiling (its mean CI above the ceiling's)."""
    ceiling = view[view["arm"] == "vision_ceiling"].set_index(_CEILING_KEY)
    exceed = []
    for r in built_on_v.itertuples():
        c = ceiling.loc[(r.corpus, r.rho, r.n_labelled, r.n_pool, r.target)]
        if r.ci_low > c["ci_high"]:
            exceed.append(f"{ARM_LABELS[(r.arm, r.probe)]} at ρ = {r.rho:g}, N_L = {r.n_labelled}")
    return "H4 (no arm built on V exceeds the vision ceiling): " + (
        "holds: no arm's mean CI lies above the ceiling's."
        if not exceed
        else f"fails in {len(exceed)} rows, e.g. {exceed[0]}."
    )


def _h5_below_v_ceiling(view: pd.DataFrame, built_on_v: pd.DataFrame) -> str:
    """H5: no arm built on V exceeds the V ceiling (the best probe on V with every label)."""
    v_ceiling = arm_rows(view, "v_ceiling", "nonlinear").set_index(_CEILING_KEY)
    above = [
        f"{ARM_LABELS[(r.arm, r.probe)]} at ρ = {r.rho:g}, N_L = {r.n_labelled}"
        for r in built_on_v.itertuples()
        if r.ci_low > v_ceiling.loc[(r.corpus, r.rho, r.n_labelled, r.n_pool, r.target), "ci_high"]
    ]
    return (
        "H5 (no arm built on V exceeds the V ceiling, nonlinear V with every non-test label): "
        + (
            "holds: no arm's mean CI lies above it."
            if not above
            else f"fails in {len(above)} rows, e.g. {above[0]}: an arm beats a probe on V with "
            "every label, so it carries what V does not."
        )
    )
