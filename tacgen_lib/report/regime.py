"""The report page *Where generated touch helps* (`tacgen_lib.generate.regime`): the visibility
gate and the verdict read from the generator ladder, Delta heatmaps over (rho, N_L) per pool
size, score against N_L per arm with the V ceiling, the vision ceiling and real touch, the
ladder table, the table of every arm, and a sentence per panel generated from the numbers. The
arms' labels are in `tacgen_lib.report.regime_arms`, the figures in
`tacgen_lib.report.regime_figures`, the hypotheses' sentences in
`tacgen_lib.report.regime_hypotheses`.

Replicates (seed x labelled draw) are summarised, never averaged into a claim: a cell shows
the mean over replicates and how many replicates' fixed-test CIs lie above (or below) zero.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt
from tacgen_lib.report.regime_arms import ARM_LABELS, RUNG_LABELS, arm_rows, gains
from tacgen_lib.report.regime_figures import curves_figure, heatmap_figure
from tacgen_lib.report.regime_hypotheses import hypothesis_sentences, replicate_words
from tacgen_lib.report.regime_pool import pool_curve_figure, pool_table, pool_verdict

__all__ = [
    "ARM_LABELS",
    "ladder_table",
    "headroom_cells",
    "WITHIN_NOISE",
    "LadderReading",
    "ladder_readings",
    "ladder_verdict",
    "arm_rows",
    "curves_figure",
    "heatmap_figure",
    "hypothesis_sentences",
    "panel_sentences",
    "pool_curve_figure",
    "pool_table",
    "pool_verdict",
    "replicate_words",
    "regime_table",
    "seed_view",
]

_CELL = ["corpus", "rho", "n_labelled", "n_pool", "target", "arm", "probe"]


def _side_counts(lo: pd.Series, hi: pd.Series) -> tuple[int, int]:
    return int((lo > 0).sum()), int((hi < 0).sum())


def seed_view(summary: pd.DataFrame) -> pd.DataFrame:
    """One row per cell x target x arm over its replicates (seed x labelled draw): mean
    score, CI bounds, Deltas, headroom captured and majority score, how many replicates fall
    below the majority score (``n_below_majority``), per Delta how many replicates' CIs lie
    above / below 0 (``above_vs_*``, ``below_vs_*``) and the replicates' interval read as one
    (``rep_low_vs_*``, ``rep_high_vs_*``: `claims.seeds_interval`, every replicate's CI and,
    from three on, the mean's t-interval over them); ``n_seeds`` counts the replicates."""
    out = []
    if "draw" not in summary:
        summary = summary.assign(draw=0)
    for key, g in summary.groupby(_CELL, sort=True):
        row = dict(zip(_CELL, key, strict=True))
        row["metric"] = g["metric"].iloc[0]
        row["n_seeds"] = len(g[["seed", "draw"]].drop_duplicates())
        for col in ("score", "ci_low", "ci_high", "gap_closed", "headroom_captured", "majority"):
            row[col] = float(g[col].mean()) if col in g else float("nan")
        row["n_below_majority"] = int(g["below_majority"].sum()) if "below_majority" in g else 0
        for what in ("linear_v", "nonlinear_v", "distilled"):
            row[f"delta_vs_{what}"] = float(g[f"delta_vs_{what}"].mean())
            row[f"above_vs_{what}"], row[f"below_vs_{what}"] = _side_counts(
                g[f"ci_low_vs_{what}"], g[f"ci_high_vs_{what}"]
            )
            # the replicates read as one (claims.seeds_interval): what a gain is decided on
            _, row[f"rep_low_vs_{what}"], row[f"rep_high_vs_{what}"] = claims.seeds_interval(
                g[f"delta_vs_{what}"], g[f"ci_low_vs_{what}"], g[f"ci_high_vs_{what}"]
            )
        out.append(row)
    return pd.DataFrame(out)


#: What the page shows for headroom captured where the V ceiling's headroom is within its noise.
WITHIN_NOISE = "headroom within noise"


def headroom_cells(sub: pd.DataFrame, view: pd.DataFrame) -> list[object]:
    """The headroom captured of each `seed_view` row of `sub` as the page shows it: the mean
    over replicates where the cell's headroom (V ceiling − nonlinear V, the nonlinear V
    ceiling's row of `view`) exceeds its noise over the replicates (`regime_arms.gains`: their interval
    read as one lies above 0) and some replicate's own CI did too (`regime_arms.
    headroom_captured`); `WITHIN_NOISE` otherwise, so the reader sees why no ratio is given."""
    keys = ["corpus", "rho", "n_labelled", "n_pool", "target"]
    ceiling = arm_rows(view, "v_ceiling", "nonlinear").set_index(keys)
    out: list[object] = []
    for _, r in sub.iterrows():
        key = tuple(r[k] for k in keys)
        beyond = key in ceiling.index and gains(ceiling.loc[key])
        value = float(r["headroom_captured"])
        out.append(value if beyond and pd.notna(value) else WITHIN_NOISE)
    return out


def _counts(r: pd.Series, what: str) -> str:
    n, up, down = int(r["n_seeds"]), int(r[f"above_vs_{what}"]), int(r[f"below_vs_{what}"])
    return f"{up}/{n} ↑, {down}/{n} ↓"


def regime_table(view: pd.DataFrame) -> pd.DataFrame:
    """Every arm at the largest pool, the smallest and largest labelled sets, per rho and
    target: mean score [mean CI], the Deltas against linear V, nonlinear V and distillation
    (mean over replicates, with how many replicates' CIs lie above / below 0), the gap
    closed, the headroom captured, and the majority score with how many replicates fall below
    it."""
    n_p = view["n_pool"].max()
    ls = sorted(view["n_labelled"].unique())
    sub = view[(view["n_pool"] == n_p) & view["n_labelled"].isin({ls[0], ls[-1]})]
    order = {k: i for i, k in enumerate(ARM_LABELS)}
    sub = sub.assign(_o=[order[(a, p)] for a, p in zip(sub["arm"], sub["probe"], strict=True)])
    sub = sub.sort_values(["target", "rho", "n_labelled", "_o"])
    ceiling = sub["arm"].isin(["v_ceiling", "vision_ceiling"])
    return pd.DataFrame(
        {
            "target": sub["target"],
            "ρ": [f"{r:g}" for r in sub["rho"]],
            "N_L": sub["n_labelled"],
            "N_P": sub["n_pool"],
            "arm": [ARM_LABELS[(a, p)] for a, p in zip(sub["arm"], sub["probe"], strict=True)],
            "score [mean 95% CI]": [
                fmt.with_ci(r.score, r.ci_low, r.ci_high) for r in sub.itertuples()
            ],
            "Δ vs linear V": sub["delta_vs_linear_v"],
            "replicates' CI vs linear V": [_counts(r, "linear_v") for _, r in sub.iterrows()],
            "Δ vs nonlinear V": sub["delta_vs_nonlinear_v"],
            "replicates' CI vs nonlinear V": [_counts(r, "nonlinear_v") for _, r in sub.iterrows()],
            "Δ vs distillation": sub["delta_vs_distilled"],
            "replicates' CI vs distillation": [_counts(r, "distilled") for _, r in sub.iterrows()],
            # the ceilings are bounds, not arms that close a gap
            "gap closed": sub["gap_closed"].where(~ceiling),
            "headroom captured": [
                float("nan") if c else h
                for c, h in zip(ceiling, headroom_cells(sub, view), strict=True)
            ],
            "majority score": sub["majority"],
            "below majority": [
                f"{int(r.n_below_majority)}/{int(r.n_seeds)}" for r in sub.itertuples()
            ],
        }
    )


def ladder_table(view: pd.DataFrame) -> pd.DataFrame:
    """The ladder at the largest pool, per target, rho and the smallest and largest labelled
    sets: nonlinear V, each rung (linear probe) from the look oracle down to one diffusion
    sample, V + real T and the V ceiling, each with its Delta against nonlinear V and how
    many replicates' CIs lie above / below 0, and the headroom captured."""
    n_p = view["n_pool"].max()
    ls = sorted(view["n_labelled"].unique())
    sub = view[(view["n_pool"] == n_p) & view["n_labelled"].isin({ls[0], ls[-1]})]
    arms = [
        ("v", "nonlinear"),
        *((rung, "linear") for rung in RUNG_LABELS),
        ("v_treal", "linear"),
        ("v_ceiling", "nonlinear"),
    ]
    out = []
    for (target, rho, n_l), g in sub.groupby(["target", "rho", "n_labelled"], sort=True):
        for arm, probe in arms:
            r = arm_rows(g, arm, probe)
            if r.empty:
                continue
            r = r.iloc[0]
            # a rung's share of the ceiling's headroom (the page's reading, `headroom_cells`)
            rung = arm in RUNG_LABELS
            headroom = headroom_cells(r.to_frame().T, view)[0] if rung else float("nan")
            out.append(
                {
                    "target": target,
                    "ρ": f"{rho:g}",
                    "N_L": int(n_l),
                    "rung": ARM_LABELS[(arm, probe)],
                    "score [mean 95% CI]": fmt.with_ci(r.score, r.ci_low, r.ci_high),
                    "Δ vs nonlinear V": r["delta_vs_nonlinear_v"],
                    "replicates' CI vs nonlinear V": _counts(r, "nonlinear_v"),
                    "headroom captured": headroom,
                    "majority score": r["majority"],
                }
            )
    return pd.DataFrame(out)


#: What each step down the ladder says where the gain is lost (generate.ladder).
_LOSS = {
    "knn": "vision: V's neighbourhoods do not hold what the look shows",
    "ridge": "a linear map from V does not carry it",
    "kernel_ridge": (
        "a nonlinear regression of T on V learnt from the pool (RBF kernel ridge, tuned by CV "
        "on the pool) does not carry it"
    ),
    "gen_mean": "the diffusion generator does not learn it",
    "v_tgen": "sampling noise (one sample instead of the mean) or the probe loses it",
}


@dataclass(frozen=True)
class LadderReading:
    """The ladder of one target at the largest pool, the largest rho and the smallest N_L:
    the look oracle's rows there and at the smallest rho, whether the positive control works
    (the oracle gains over nonlinear V there, and does not at the smallest rho, a gain being
    read over the replicates, `regime_arms.gains`: one replicate's CI above 0 by chance at the smallest
    rho, about one in twenty, does not undo the control),
    and the first rung below the oracle that loses the gain (None: every rung keeps it)."""

    target: str
    where: str
    top: pd.DataFrame
    a0: pd.Series
    a0_low: pd.Series
    control: bool
    lost: str | None


def ladder_readings(view: pd.DataFrame) -> list[LadderReading]:
    """The `LadderReading` of every target whose look oracle ran (`seed_view` rows)."""
    out = []
    rhos = sorted(view["rho"].unique())
    ls = sorted(view["n_labelled"].unique())
    n_p = view["n_pool"].max()
    big = view[view["n_pool"] == n_p]
    for target, t in big.groupby("target", sort=True):
        top = t[(t["rho"] == rhos[-1]) & (t["n_labelled"] == ls[0])]
        low = t[(t["rho"] == rhos[0]) & (t["n_labelled"] == ls[0])]
        a0, a0_low = arm_rows(top, "look_oracle", "linear"), arm_rows(low, "look_oracle", "linear")
        if a0.empty or a0_low.empty:
            continue
        a0, a0_low = a0.iloc[0], a0_low.iloc[0]
        control = gains(a0) and not gains(a0_low)
        rungs = list(RUNG_LABELS)
        lost = next((r for r in rungs[1:] if not gains(arm_rows(top, r, "linear").iloc[0])), None)
        where = f"{target}, ρ = {rhos[-1]:g}, N_L = {ls[0]}, N_P = {n_p}"
        out.append(LadderReading(str(target), where, top, a0, a0_low, control, lost))
    return out


def ladder_verdict(
    view: pd.DataFrame, gates: Sequence[str] = (), gate_passed: bool = True
) -> list[str]:
    """The page's verdict, generated from the ladder (linear probe, largest pool):

    1. the visibility gate (`gates`: its sentences; `gate_passed`: whether V passed it);
    2. the positive control: the look oracle (A0) at the largest rho and the smallest N_L
       gains over nonlinear V (`regime_arms.gains`: over the replicates), and at the smallest rho does not;
       without it, no claim about generated touch is made;
    3. only then, per target, how far down the ladder the gain survives and which rung
       loses it; where V failed the gate, that the regime cannot say whether generated touch
       helps.
    """
    out = list(gates)
    rho_lo = view["rho"].min()
    for r in ladder_readings(view):
        a0, a0_low, top = r.a0, r.a0_low, r.top
        if not r.control:
            why = (
                "A generator with perfect vision shows no gain the probes detect, so the regime "
                "cannot say whether generated touch helps: the probe or the evaluation lacks "
                "the power."
                if not gains(a0)
                else f"The look gains at ρ = {rho_lo:g} too, where appearance says nothing of "
                "the material: the gain is not the look's, so the regime cannot say whether "
                "generated touch helps."
            )
            out.append(
                f"Positive control fails ({r.where}): the look oracle (A0) − nonlinear V "
                f"{replicate_words(a0, 'nonlinear_v')}; at ρ = {rho_lo:g} "
                f"{replicate_words(a0_low, 'nonlinear_v')}. {why}"
            )
            continue
        out.append(
            f"Positive control works ({r.where}): the look oracle (A0) − nonlinear V "
            f"{replicate_words(a0, 'nonlinear_v')}, and no gain at ρ = {rho_lo:g} "
            f"({replicate_words(a0_low, 'nonlinear_v')}): the probes detect a gain that exists."
        )
        gen = arm_rows(top, "v_tgen", "linear").iloc[0]
        if r.lost is None:
            out.append(
                f"{r.target}: every rung down to one diffusion sample (A3) keeps the gain "
                f"({replicate_words(gen, 'nonlinear_v')} against nonlinear V)."
                + (
                    ""
                    if gate_passed
                    else " V failed the visibility gate, so this holds for this V only."
                )
            )
            continue
        rungs = list(RUNG_LABELS)
        kept = rungs[: rungs.index(r.lost)]
        lost = arm_rows(top, r.lost, "linear").iloc[0]
        out.append(
            f"{r.target}: the gain survives down to {RUNG_LABELS[kept[-1]]} and is lost at "
            f"{RUNG_LABELS[r.lost]} ({replicate_words(lost, 'nonlinear_v')} against nonlinear V): "
            f"{_LOSS[r.lost]}."
            + (
                f" The workflow's own generator (A3) − nonlinear V "
                f"{replicate_words(gen, 'nonlinear_v')}."
            )
            + (
                ""
                if gate_passed
                else " V failed the visibility gate: the regime cannot say whether generated "
                "touch would help a V that sees the look."
            )
        )
    return out


def panel_sentences(view: pd.DataFrame) -> list[str]:
    """One sentence per heatmap panel (target x pool size), read from the numbers: where V +
    T_gen gains over linear V, whether that survives nonlinear V and distillation."""
    out = []
    gen = arm_rows(view, "v_tgen", "linear")
    for (target, n_p), g in gen.groupby(["target", "n_pool"], sort=True):
        wins = g[g["above_vs_linear_v"] == g["n_seeds"]]
        if wins.empty:
            out.append(
                f"{target}, N_P = {n_p}: V + T_gen (linear probe) beats linear V with its CI above "
                "0 in every replicate in no cell of ρ × N_L."
            )
            continue
        cells = ", ".join(f"ρ = {r.rho:g} / N_L = {r.n_labelled}" for r in wins.itertuples())
        survive_nl = wins[wins["above_vs_nonlinear_v"] == wins["n_seeds"]]
        survive_gd = wins[wins["above_vs_distilled"] == wins["n_seeds"]]
        out.append(
            f"{target}, N_P = {n_p}: V + T_gen (linear probe) beats linear V in every replicate at "
            f"{cells}; of these, {len(survive_nl)} also beat nonlinear V and {len(survive_gd)} "
            "beat generalised distillation (a V-only student of the same pool) in every replicate."
        )
    return out


def findings_notes(
    view: pd.DataFrame,
    gates: Sequence[str] = (),
    gate_passed: bool = True,
    *,
    control: pd.DataFrame | None = None,
    snr: float | None = None,
) -> list[str]:
    """The page's sentences: the gate and the ladder's verdict (`ladder_verdict`), the
    verdict against the pool size with its positive control where `control` holds it
    (`pool_verdict`), the hypotheses, one per panel."""
    return [
        *ladder_verdict(view, gates, gate_passed),
        *pool_verdict(view, control, snr),
        *hypothesis_sentences(view),
        *panel_sentences(view),
    ]


def findings_table(notes: Sequence[str]) -> pd.DataFrame:
    return pd.DataFrame({"finding (generated from the numbers)": list(notes)})
