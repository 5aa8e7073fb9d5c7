"""The findings page's rows of the regime branch (`tacgen_lib.report.findings` gathers every
branch's): where generated touch helps (`regime_findings`: V + T_gen against V at the cell
where it should help most, with the controls that could explain a gain away and the ladder's
verdict) and what vision sees (`visibility_findings`, against the visibility gate).
"""

from __future__ import annotations

from collections.abc import Mapping

import pandas as pd

from tacgen_lib.report.decisions import FindingsPart, decision, side_decision
from tacgen_lib.report.regime_arms import RUNG_LABELS, arm_rows
from tacgen_lib.report_pages import FINDINGS_COLUMNS, category

__all__ = ["regime_findings", "visibility_findings"]


def _regime_row(rows: pd.DataFrame, arm: str, probe: str = "linear") -> pd.Series:
    return arm_rows(rows, arm, probe).iloc[0]


def replicates_decision(r: pd.Series, what: str) -> str:
    """A `seed_view` row's Δ against `what` read over its replicates (seed × labelled draw):
    ``above 0`` / ``below 0`` where the replicates' interval read as one lies there
    (``rep_low_vs_*``, ``rep_high_vs_*``: every replicate's CI, and from three on the mean's
    t-interval over them), else ``no measurable difference``: one draw of the labelled rows
    decides nothing, nor a gain the replicates' spread does not support."""
    return side_decision(r[f"rep_low_vs_{what}"], r[f"rep_high_vs_{what}"])


def _ladder_decisions(view: pd.DataFrame) -> list[dict]:
    """Per target, the ladder's two decisions (`report.regime.ladder_readings`): whether the
    positive control works, and where the gain is lost."""
    from tacgen_lib.report.regime import ladder_readings

    out = []
    for r in ladder_readings(view):
        out.append(
            decision(
                f"regime|{r.target}|positive_control",
                "regime",
                f"look oracle − nonlinear V above 0 over the replicates, and not at the smallest "
                f"ρ ({r.where})",
                "works" if r.control else "fails",
                value=r.a0["delta_vs_nonlinear_v"],
                ci_low=r.a0["rep_low_vs_nonlinear_v"],
                ci_high=r.a0["rep_high_vs_nonlinear_v"],
                threshold=0.0,
            )
        )
        lost = "not read: no positive control"
        if r.control:
            lost = "kept to A3" if r.lost is None else f"lost at {RUNG_LABELS[r.lost]}"
        out.append(
            decision(
                f"regime|{r.target}|ladder",
                "regime",
                f"the first rung of the ladder that loses the look oracle's gain ({r.where})",
                lost,
            )
        )
    return out


def _pool_decisions(view: pd.DataFrame, control: pd.DataFrame | None) -> list[dict]:
    """Per target, where two or more pool sizes ran: the smallest pool at which a learnt rung
    and at which the diffusion model gain over nonlinear V over the replicates
    (`report.regime_pool.first_gain`, at the largest rho and the N_L the curve is read at,
    `report.regime_pool.reading_n_labelled`); and where `control` (the positive control's
    `seed_view`) holds the target, the same for its learnt rungs."""
    from tacgen_lib.report.regime_pool import (
        DIFFUSION_RUNGS,
        LEARNT_RUNGS,
        first_gain,
        reading_n_labelled,
    )

    pools = sorted(int(n) for n in view["n_pool"].unique())
    if len(pools) < 2:
        return []
    rho = view["rho"].max()
    out = []
    controlled = set(control["target"]) if control is not None else set()
    for target in sorted(view["target"].unique()):
        n_l = reading_n_labelled(view, target, rho)
        curves = [("learnt", LEARNT_RUNGS, view, ""), ("diffusion", DIFFUSION_RUNGS, view, "")]
        if target in controlled:
            curves.append(("control_learnt", LEARNT_RUNGS, control, "; positive control"))
        for kind, rungs, source, what in curves:
            found = first_gain(source, target, rho, n_l, rungs)
            out.append(
                decision(
                    f"regime|{target}|pool_first_gain_{kind}",
                    "regime",
                    f"the smallest N_P at which a {kind.removeprefix('control_')} rung gains "
                    f"over nonlinear V over the replicates ({target}, ρ = {rho:g}, N_L = "
                    f"{n_l}, N_P {pools[0]}–{pools[-1]}{what})",
                    f"none up to {pools[-1]}"
                    if found is None
                    else f"N_P = {found[0]} ({RUNG_LABELS[found[1]]})",
                )
            )
    return out


def regime_findings(
    summary: pd.DataFrame,
    gate_sentence: str = "",
    gate_passed: bool = True,
    *,
    control: pd.DataFrame | None = None,
    snr: float | None = None,
) -> FindingsPart:
    """Per regime target, where generated touch should help most: the largest rho, the fewest
    labels, the largest pool. V + T_gen (linear probe) against linear V, with the controls
    that could explain a gain away beside it: the shuffled-pool generator, nonlinear V,
    generalised distillation (the pool used without generating), the same cell at the smallest
    rho; the positive control (the look oracle against nonlinear V) and the ladder's verdict
    (`report.regime.ladder_verdict`) with the visibility gate's sentence `gate_sentence`. Every figure
    is the mean over the cell's replicates (seed × labelled draw) with how many replicates'
    CIs lie above or below 0, and each decision reads every replicate (`replicates_decision`):
    one draw of the labelled rows decides nothing. `control`: the positive control's rows of
    the curve against the pool size (rule regime_look_control, built at `snr`), where it ran."""
    from tacgen_lib.report.regime import ladder_verdict, pool_verdict, replicate_words, seed_view

    rows, decided = [], []
    if summary.empty:
        return FindingsPart(pd.DataFrame(rows, columns=FINDINGS_COLUMNS), decided)
    view = seed_view(summary)
    control_view = seed_view(control) if control is not None and len(control) else None

    def pool_words(target: str) -> list[str]:  # the curve's verdict, where it has one
        if view["n_pool"].nunique() < 2:
            return []
        return pool_verdict(view[view["target"] == target], control_view, snr)

    rho_hi, rho_lo = view["rho"].max(), view["rho"].min()
    n_l, n_p = view["n_labelled"].min(), view["n_pool"].max()
    cell = view[(view["n_labelled"] == n_l) & (view["n_pool"] == n_p)]
    for target, g in cell.groupby("target", sort=True):
        hi, lo = g[g["rho"] == rho_hi], g[g["rho"] == rho_lo]
        gen, shuf = _regime_row(hi, "v_tgen"), _regime_row(hi, "v_tgen_shuffled")
        gd, gen_lo = _regime_row(hi, "distilled"), _regime_row(lo, "v_tgen")
        oracle = _regime_row(hi, "look_oracle")
        ladder = ladder_verdict(view[view["target"] == target], gate_passed=gate_passed)
        where = f"{target}, ρ = {rho_hi:g}, N_L = {n_l}, N_P = {n_p}"
        reading = replicates_decision(gen, "linear_v")
        decided.append(
            decision(
                f"regime|{target}|v_tgen_vs_linear_v",
                "regime",
                f"V + T_gen − linear V over the replicates ({where})",
                reading,
                value=gen["delta_vs_linear_v"],
                ci_low=gen["rep_low_vs_linear_v"],
                ci_high=gen["rep_high_vs_linear_v"],
                threshold=0.0,
            )
        )
        n = int(gen["n_seeds"])
        rows.append(
            {
                "evidence": "regime",
                "question": f"does touch generated by a generator trained on an unlabelled "
                f"pool help a probe on few labels where appearance predicts material? "
                f"({target}, {gen['metric']}; ρ = {rho_hi:g}, N_L = {n_l}, N_P = {n_p}, "
                f"mean of {n} replicates: seed × labelled draw)",
                "result": f"V + T_gen − linear V {replicate_words(gen, 'linear_v')}; − nonlinear V "
                f"{replicate_words(gen, 'nonlinear_v')}; − distillation "
                f"{replicate_words(gen, 'distilled')}",
                "control": f"positive control: look oracle − nonlinear V "
                f"{replicate_words(oracle, 'nonlinear_v')}; shuffled pool − linear V "
                f"{replicate_words(shuf, 'linear_v')}; distillation (V only) − linear V "
                f"{replicate_words(gd, 'linear_v')}; V + T_gen at ρ = {rho_lo:g} − linear V "
                f"{replicate_words(gen_lo, 'linear_v')}",
                "verdict": " ".join([gate_sentence, *ladder, *pool_words(target)]).strip()
                + f" Over the replicates, V + T_gen − linear V: {reading}.",
                "page": category("Where generated touch helps"),
            }
        )
    decided += _ladder_decisions(view) + _pool_decisions(view, control_view)
    return FindingsPart(pd.DataFrame(rows, columns=FINDINGS_COLUMNS), decided)


def visibility_findings(rows: pd.DataFrame, gate: Mapping[str, float]) -> FindingsPart:
    """One row: what V decodes of what the frames show, on the first corpus with an
    appearance class (the regime's; else the first corpus checked), against the gate; a
    decision per factor of the gate and one for the gate."""
    from tacgen_lib.generate.visibility import visibility_gate
    from tacgen_lib.report.visibility import visibility_sentence

    if rows.empty:
        return FindingsPart(pd.DataFrame([], columns=FINDINGS_COLUMNS), [])
    with_class = sorted(rows.loc[rows["factor"] == "appearance", "corpus"].unique())
    corpus = with_class[0] if with_class else sorted(rows["corpus"].unique())[0]
    decided = []
    verdict = ""
    if gate:
        passed = visibility_gate(rows, corpus, gate)
        verdict = passed.sentence()
        for factor, threshold in passed.thresholds.items():
            score = passed.scores[factor]
            decided.append(
                decision(
                    f"visibility|{corpus}|{factor}",
                    "visibility",
                    f"V's test accuracy on {factor}, the better of the two probes ({corpus})",
                    "passes" if score >= threshold else "fails",
                    value=score,
                    threshold=threshold,
                )
            )
        decided.append(
            decision(
                f"visibility|{corpus}|gate",
                "visibility",
                f"the visibility gate ({corpus})",
                "passes" if passed.passed else "fails",
            )
        )
    return FindingsPart(
        pd.DataFrame(
            [
                {
                    "evidence": "visibility",
                    "question": f"does V see what the frames show? ({corpus}, test accuracy, "
                    "better of a linear and a nonlinear probe on every non-test row)",
                    "result": visibility_sentence(rows, corpus),
                    "control": "each factor's majority class (beside each figure)",
                    "verdict": verdict or "No gate is configured (features.visibility.gate).",
                    "page": category("What vision sees"),
                }
            ],
            columns=FINDINGS_COLUMNS,
        ),
        decided,
    )
