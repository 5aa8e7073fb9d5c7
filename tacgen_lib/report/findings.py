"""The findings page: the headline results of every evidence branch in one table, each with
its control beside it and a verdict sentence generated from the numbers (`claims`), and the
decisions those verdicts state (`tacgen_lib.report.decisions`), written beside the page as an
edge so that two runs can be compared by their conclusions.

One row per finding: probes and generation (`tacgen_lib.report.findings_probes`), policy (V+T
against V with the null-touch control; V-only against the vision-only ceiling), backbone
families, transfer to a second sensor, pixel generators; the regime's and the visibility
check's rows (`tacgen_lib.report.findings_regime`). Each branch's function returns a
`decisions.FindingsPart`; `gather` joins them. Pure functions over the stages' summary edges;
none reads files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from tacgen_lib.probes.transfer import beats_shuffled_control
from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt
from tacgen_lib.report.backbones import direction_holds, null_gains
from tacgen_lib.report.decisions import FindingsPart, decision, decisions_frame, side_decision
from tacgen_lib.report.findings_probes import generation_findings, probe_findings
from tacgen_lib.report.findings_regime import regime_findings, visibility_findings
from tacgen_lib.report_pages import FINDINGS_COLUMNS, category

__all__ = [
    "FINDINGS_COLUMNS",
    "gather",
    "probe_findings",
    "generation_findings",
    "policy_findings",
    "regime_findings",
    "visibility_findings",
    "backbone_findings",
    "transfer_findings",
    "pixel_findings",
]


def _success(r: Mapping) -> str:
    # claims' function, not report.policy's wrapper: that module pulls in MuJoCo (seconds of imports)
    return claims.proportion_with_ci(r["success"], r["ci_low"], r["ci_high"], int(r["n_episodes"]))


def policy_findings(
    summary: pd.DataFrame, deltas: pd.DataFrame, sweep: pd.DataFrame
) -> FindingsPart:
    """V+T (aligned) against V on the same held-out episodes with the null-touch control, and
    the V-only policy against the vision-only ceiling."""
    d = deltas.set_index("condition")
    s = summary.drop_duplicates("condition").set_index("condition")
    rows, decided = [], []
    if "vt_aligned" in d.index and "v" in s.index:
        r, v, vt = d.loc["vt_aligned"], s.loc["v"], s.loc["vt_aligned"]
        null = d.loc["vt_null"] if "vt_null" in d.index else None
        decided.append(
            decision(
                "policy|vt_aligned",
                "policy",
                "success of V+T (aligned) − V on the held-out episodes",
                side_decision(r["ci_low"], r["ci_high"]),
                value=r["delta"],
                ci_low=r["ci_low"],
                ci_high=r["ci_high"],
                threshold=0.0,
            )
        )
        rows.append(
            {
                "evidence": "policy",
                "question": "does touch let a grasping policy succeed where vision alone "
                f"cannot? ({int(r['n_episodes'])} held-out episodes)",
                "result": f"success V {_success(v)} → V+T {_success(vt)}; Δ "
                f"{fmt.with_ci(r['delta'], r['ci_low'], r['ci_high'], sign=True)}",
                "control": "another episode's touch (vt_null) Δ "
                + (
                    fmt.with_ci(null["delta"], null["ci_low"], null["ci_high"], sign=True)
                    if null is not None
                    else fmt.MISSING
                ),
                "verdict": claims.delta_verdict(
                    r["delta"], r["ci_low"], r["ci_high"], what="Touch"
                ),
                "page": category("Policy"),
            }
        )
    if "v" in s.index and len(sweep):
        v = s.loc["v"]
        best = sweep.loc[sweep["success"].idxmax()]
        ceiling = float(sweep["vision_ceiling"].iloc[0])
        decided.append(
            decision(
                "policy|v_ceiling",
                "policy",
                "V-only success against the vision-only ceiling",
                claims.ceiling_decision(v["success"], v["ci_low"], v["ci_high"], ceiling),
                value=v["success"],
                ci_low=v["ci_low"],
                ci_high=v["ci_high"],
                threshold=ceiling,
            )
        )
        rows.append(
            {
                "evidence": "policy",
                "question": "is the V-only policy limited by what vision sees, not by capacity?",
                "result": f"V-only success {fmt.with_ci(v['success'], v['ci_low'], v['ci_high'])}; "
                f"best of the capacity sweep {fmt.number(best['success'])}, closing "
                f"{fmt.signed(best['gap_closed'])} of the V → V+T gap",
                "control": f"vision-only ceiling {fmt.number(ceiling)} (expected success of the "
                "best force given the visible size)",
                "verdict": claims.ceiling_verdict(v["success"], v["ci_low"], v["ci_high"], ceiling),
                "page": category("Policy"),
            }
        )
    return FindingsPart(pd.DataFrame(rows, columns=FINDINGS_COLUMNS), decided)


def backbone_findings(
    summary: pd.DataFrame, main: Sequence[str], order: Sequence[str] = ()
) -> FindingsPart:
    """One row per backbone family other than the main DAG's (whose rows are the probes
    stage's, already on this page): V+T − V under the linear probe on each real-corpus probe
    family, the null corpus's probe families of the same targets as the control, and the
    verdict of the family's sentence (`report.backbones.direction_holds`, `null_gains`).
    Families in `order` (config backbones.run), then any other."""
    rows, decided = [], []
    linear = summary[(summary["protocol"] == "raw") & (summary["status"] == "ok")]
    for family in dict.fromkeys([*order, *linear["family"]]):
        if family in main:
            continue
        g = linear[linear["family"] == family]
        if g.empty:
            continue
        real, null = g[~g["null_corpus"]], g[g["null_corpus"]]

        def deltas(part: pd.DataFrame) -> str:
            return "; ".join(
                f"{x.probe} {fmt.with_ci(x.delta, x.ci_low, x.ci_high, sign=True)}"
                for x in part.itertuples()
            )

        first = g.iloc[0]
        holds = direction_holds(summary[summary["family"] == family])
        verdict = (
            "The V+T direction holds: Δ > 0 on every real-corpus probe."
            if holds
            else "The V+T direction does not hold on every real-corpus probe."
        )
        above = null_gains(null)
        decided += [
            decision(
                f"backbones|{family}|direction",
                "backbone families",
                f"V+T − V > 0 on every real-corpus probe ({family}, linear probe)",
                "holds" if holds else "does not hold",
                value=float(real["delta"].min()) if len(real) else np.nan,
                threshold=0.0,
            ),
            decision(
                f"backbones|{family}|null_gains",
                "backbone families",
                f"null-corpus probes with V+T − V CI above 0 ({family})",
                ", ".join(sorted(above["probe"])) or "none",
                value=float(len(above)),
            ),
        ]
        if len(above):
            verdict += f" UNEXPECTED: a null-corpus CI lies above 0 ({', '.join(above['probe'])})."
        rows.append(
            {
                "evidence": "backbone families",
                "question": f"does touch add to vision with another encoder family? ({family}: "
                f"V {first['vision_backbone']}, T {first['tactile_backbone']}; linear probe)",
                "result": f"V+T − V: {deltas(real)}" if len(real) else "no real-corpus probe",
                "control": f"null corpus V+T − V: {deltas(null)}" if len(null) else "none",
                "verdict": verdict,
                "page": category("Backbone families"),
            }
        )
    return FindingsPart(pd.DataFrame(rows, columns=FINDINGS_COLUMNS), decided)


def _over_heads_seeds(means: pd.DataFrame, view: str, col: str) -> tuple[float, float, float]:
    """A transfer view's probe-seed mean of `col` with its interval, read over the heads
    seeds (`claims.seeds_interval`: the heads' training draw as a replicate)."""
    g = means[means["heads"] == view]
    return claims.seeds_interval(g[col], g[f"{col}_ci_low"], g[f"{col}_ci_high"])


def transfer_findings(summary: pd.DataFrame) -> FindingsPart:
    """One row for the transfer to a second sensor (`tacgen_lib.probes.transfer`): the probe
    seeds' mean Δ balanced accuracy with the first sensor's heads and with retrained heads,
    the null corpus's heads and shuffled touch as the controls, each read over the heads
    seeds (`_over_heads_seeds`), and the verdict on the transferred heads' Δ, whether it
    beats the shuffled control and whether it beats the floor."""
    means = summary[summary["probe_seed"] == "mean"]
    if "source" not in set(means["heads"]):
        return FindingsPart(pd.DataFrame(columns=FINDINGS_COLUMNS), [])

    def delta(view: str, col: str = "delta") -> str:
        g = means[means["heads"] == view]
        if g.empty:
            return "not run"
        text = fmt.with_ci(*_over_heads_seeds(means, view, col), sign=True)
        if col != "delta":
            return text
        seeds = f"{int(g['positive_seeds'].sum())}/{int(g['n_seeds'].sum())} probe seeds > 0"
        if len(g) > 1:
            seeds += f", over {len(g)} heads seeds"
        return f"{text} ({seeds})"

    src = means[means["heads"] == "source"].iloc[0]
    d, lo, hi = _over_heads_seeds(means, "source", "delta")
    _, _, shuffled_hi = _over_heads_seeds(means, "source", "delta_shuffled")
    verdict = claims.delta_verdict(d, lo, hi)
    beats = beats_shuffled_control(lo, shuffled_hi)
    what = "with the first sensor's heads, mass tertiles of the second sensor's test objects"
    decided = [
        decision(
            "transfer|source",
            "transfer to a second sensor",
            f"V+T − V {what}, over the heads seeds",
            side_decision(lo, hi),
            value=d,
            ci_low=lo,
            ci_high=hi,
            threshold=0.0,
        ),
        decision(
            "transfer|source_vs_shuffled",
            "transfer to a second sensor",
            f"V+T − V {what}, against the shuffled-touch control's upper bound",
            "above the control" if beats else "not above the control",
            value=lo,
            threshold=shuffled_hi,
        ),
    ]
    if beats:
        verdict += " It lies above the shuffled-touch control."
    else:
        verdict += " It does not separate from the shuffled-touch control."
    if "floor" in set(means["heads"]):
        floor, _, _ = _over_heads_seeds(means, "floor", "delta")
        decided.append(
            decision(
                "transfer|source_vs_floor",
                "transfer to a second sensor",
                f"V+T − V {what}, against the null corpus's heads",
                "above the floor" if lo > floor else "not above the floor",
                value=lo,
                threshold=floor,
            )
        )
        if lo > floor:
            verdict += " The transferred heads beat the null corpus's heads."
        else:
            verdict += (
                " The null corpus's heads do as well (Δ "
                f"{fmt.signed(floor)}): what touch adds here is not what alignment learnt."
            )
    rows = pd.DataFrame(
        [
            {
                "evidence": "transfer to a second sensor",
                "question": "do heads trained on one sensor make touch add to vision on unseen "
                f"objects of another? (mass tertiles, balanced accuracy, {int(src['n_test_objects'])} "
                f"test objects, mean of {int(src['n_seeds'])} probe seeds per heads seed)",
                "result": f"heads from {src['heads_from']}: V+T − V {delta('source')}; heads "
                f"retrained on the second sensor (upper reference): {delta('target')}",
                "control": f"null corpus's heads (floor): {delta('floor')}; shuffled touch with "
                f"the transferred heads: {delta('source', 'delta_shuffled')}",
                "verdict": verdict,
                "page": category("Transfer to a second sensor"),
            }
        ],
        columns=FINDINGS_COLUMNS,
    )
    return FindingsPart(rows, decided)


def pixel_findings(summary: pd.DataFrame) -> FindingsPart:
    """One row per judged corpus for the pixel generators (`tacgen_lib.generate.pixel`): per
    target the best raw generator arm's Δ (first seed) against real touch at the generators'
    frame size, the shuffled pairing as the control, and the verdict: which arms are
    utility-positive (Δ CI above 0 and above the shuffled control's interval)."""
    from tacgen_lib.report.pixel import arm_label, utility_positive

    out, decided = [], []
    s = summary[summary["seed"] == summary["seed"].min()]
    for corpus, g in s.groupby("corpus", sort=True):
        arm = g["arm"].astype(str)
        gens = g[(arm == "pix2pix") | arm.str.startswith("ddpm_")]
        gens = gens[~gens["arm"].str.endswith("_cal")]
        results, controls, positive, real_helps = [], [], [], []
        for target, t in gens.groupby("target", sort=True):
            best = t.loc[t["delta"].idxmax()]
            results.append(
                f"{target}: {arm_label(best['arm'])} "
                f"{fmt.with_ci(best['delta'], best['ci_low'], best['ci_high'], sign=True)}"
            )
            ref = g[(g["target"] == target) & (g["arm"] == "real_lowres")]
            if len(ref):
                r = ref.iloc[0]
                real_helps.append(bool(r["ci_low"] > 0))
                controls.append(
                    f"{target}: real frames at the generators' size "
                    f"{fmt.with_ci(r['delta'], r['ci_low'], r['ci_high'], sign=True)}, shuffled "
                    f"pairing {fmt.signed(best['shuffled_delta'])}"
                )
            positive += [
                f"{arm_label(x.arm)} ({target})" for x in t.itertuples() if utility_positive(x)
            ]
        decided += [
            decision(
                f"pixel|{corpus}|utility_positive",
                "pixel generators",
                f"pixel generator arms with V + T_gen − V above 0 and above the shuffled "
                f"control ({corpus})",
                ", ".join(sorted(positive)) or "none",
                value=float(len(positive)),
            ),
            decision(
                f"pixel|{corpus}|real_lowres",
                "pixel generators",
                f"real frames at the generators' size add to vision on every target ({corpus})",
                "yes" if real_helps and all(real_helps) else "no",
            ),
        ]
        verdict = (
            "Utility-positive: " + ", ".join(positive) + "."
            if positive
            else "No pixel generator adds to vision here (no Δ CI above 0 and above its "
            "shuffled control)"
            + (
                ", while real touch at the same frame size does: what is missing is not resolution."
                if real_helps and all(real_helps)
                else "."
            )
        )
        out.append(
            {
                "evidence": "pixel generators",
                "question": f"does a generated tactile frame add to vision? ({corpus}, Pix2Pix "
                "and pixel DDPM, V + T_gen − V, the best arm per target)",
                "result": "; ".join(results),
                "control": "; ".join(controls),
                "verdict": verdict,
                "page": category("Pixel generators"),
            }
        )
    return FindingsPart(pd.DataFrame(out, columns=FINDINGS_COLUMNS), decided)


def gather(parts: Sequence[FindingsPart]) -> FindingsPart:
    """The findings page's rows and its decisions edge (`decisions.decisions_frame`, keyed by
    ``decision_id``) from every branch's part, in the order given."""
    rows = [p.rows for p in parts if len(p.rows)]
    table = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(columns=FINDINGS_COLUMNS)
    return FindingsPart(table, decisions_frame([d for p in parts for d in p.decisions]))
