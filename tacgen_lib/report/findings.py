"""The findings page: the headline results of every evidence branch in one table, each with
its control beside it and a verdict sentence generated from the numbers (`claims`).

One row per finding: probes (per family, the comparison whose controls were run: V, V+T, Δ
with its CI, Δ_ctrl with touch permuted across rows, and the criterion), generation (per corpus × target at the
reference cell: Δ_gen over seeds against Δ_real, the shuffled-pair control and the nonlinear
V-only baseline), policy (V+T against V with the null-touch control; V-only against the
vision-only ceiling), backbone families, transfer to a second sensor, pixel generators; the
regime's and the visibility check's rows are built in `tacgen_lib.report.findings_regime`. Pure functions over the stages' summary edges; none reads files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from tacgen_lib.probes.transfer import beats_shuffled_control
from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt
from tacgen_lib.report.backbones import direction_holds, null_gains
from tacgen_lib.report.findings_regime import regime_findings, visibility_findings
from tacgen_lib.report.generate import cross_seed_interval, delta_with_ci, reference_cell_rows
from tacgen_lib.report_pages import FINDINGS_COLUMNS, category

__all__ = [
    "FINDINGS_COLUMNS",
    "probe_findings",
    "generation_findings",
    "policy_findings",
    "regime_findings",
    "visibility_findings",
    "backbone_findings",
    "transfer_findings",
    "pixel_findings",
]


def _input_label(r: Mapping) -> str:
    if r["input"] == "aligned":
        return f"aligned heads (seed {int(r['align_seed'])})"
    return "raw features"


def _flag(r: Mapping) -> str:
    flag = claims.extreme_flag(
        r["metric"],
        r["v_score"],
        r["vt_score"],
        r["ci_low"],
        r["ci_high"],
        r.get("baseline_score", np.nan),
    )
    return f" ⚠ {flag}." if flag else ""


def probe_findings(summary: pd.DataFrame) -> pd.DataFrame:
    """Per probe family and input, the headline comparison (concat fusion, the heads' tactile
    variant, controls run; the first alignment seed), with its controls' largest Δ."""
    s = summary[
        (summary["control"] == "none")
        & (summary["fusion"] == "concat")
        & (summary["t_variant"] == summary["heads_variant"])
        & summary["delta_ctrl"].notna()
        & (summary["status"] == "ok")
    ].copy()
    s["_a"] = s["align_seed"].fillna(-1)
    s = s.sort_values(["null_corpus", "family", "input", "_a"], kind="stable")
    s = s.drop_duplicates(["family", "input"], keep="first")
    rows = []
    for r in s.to_dict("records"):
        null = bool(r["null_corpus"])
        rows.append(
            {
                "evidence": "probe",
                "question": f"{r['family']}: does touch add to vision on {r['target']}? "
                f"({r['corpus']}, {_input_label(r)}, {r['metric']})",
                "result": f"V {fmt.number(r['v_score'])} → V+T {fmt.number(r['vt_score'])}; "
                f"Δ {fmt.with_ci(r['delta'], r['ci_low'], r['ci_high'], sign=True)}",
                "control": f"touch permuted across rows: Δ_ctrl {fmt.signed(r['delta_ctrl'])}"
                + ("; null corpus: touch carries no label" if null else ""),
                "verdict": claims.probe_verdict(
                    r["delta"],
                    r["ci_low"],
                    r["ci_high"],
                    null_corpus=null,
                    criterion_met=None
                    if fmt.is_missing(r["criterion_met"])
                    else bool(r["criterion_met"]),
                    delta_ctrl=r["delta_ctrl"],
                )
                + _flag(r),
                "page": category("Probes"),
            }
        )
    return pd.DataFrame(rows, columns=FINDINGS_COLUMNS)


def _first_seed(rows: pd.DataFrame, col: str = "delta") -> tuple[float, float, float]:
    """(Δ, lo, hi) of the first generator seed with its fixed-test bootstrap CI."""
    if rows is None or not len(rows):
        return (np.nan, np.nan, np.nan)
    return delta_with_ci(_first_row(rows), col)


def _first_row(rows: pd.DataFrame) -> pd.Series:
    """The first generator seed's row."""
    return rows.sort_values("seed", kind="stable").iloc[0]


def generation_findings(summary: pd.DataFrame, ref: Mapping) -> pd.DataFrame:
    """Per corpus × target at the reference sampling cell: generated touch against real touch,
    with the shuffled-pair control, the nonlinear V-only baseline and the ridge V->T generator.

    The verdict reads the first generator seed's fixed-test bootstrap CIs (they carry the test
    rows' sampling noise; real touch and the baselines do not depend on the generator seed); the
    mean over seeds with its t-interval, which carries only the seeds' spread, is shown beside."""
    s = reference_cell_rows(summary, ref)
    rows = []
    for (corpus, target), g in s.groupby(["corpus", "target"], sort=True):
        by = {k: v for k, v in g.groupby("input")}
        if not {"t_gen", "t_real"} <= set(by):
            continue
        gen, real = _first_seed(by["t_gen"]), _first_seed(by["t_real"])
        shuffled = _first_seed(by.get("t_gen_shuffled"))
        nonlin = _first_seed(by.get("v_nonlinear"))
        ridge = _first_seed(by["t_ridge"])
        vs_ridge = _first_seed(by["t_gen"], "delta_vs_ridge")
        first_rows = {k: _first_row(by[k]) for k in ("t_gen", "t_ridge", "t_ridge_residual")}
        pairing = {
            k: (float(r["cos_matched"]), float(r["cos_offdiag"])) for k, r in first_rows.items()
        }
        seeds = cross_seed_interval(by["t_gen"]["delta"].to_numpy())
        n = int(g["seed"].nunique())
        first = int(g["seed"].min())
        rows.append(
            {
                "evidence": "generation",
                "question": f"does touch generated from RGB add to vision on {target}? "
                f"({corpus}, {g['metric'].iloc[0]})",
                "result": f"Δ_gen {fmt.with_ci(*gen, sign=True)} (seed {first}"
                + (f"; mean over {n} seeds {fmt.with_ci(*seeds, sign=True)}" if n > 1 else "")
                + f"); Δ_real {fmt.with_ci(*real, sign=True)}",
                "control": f"shuffled pairs Δ {fmt.with_ci(*shuffled, sign=True)}; nonlinear "
                f"V only Δ {fmt.with_ci(*nonlin, sign=True)}; ridge V→T generator Δ "
                f"{fmt.with_ci(*ridge, sign=True)}",
                "verdict": claims.generation_verdict(gen, real, nonlin)
                + _flag(
                    {
                        **first_rows["t_gen"].to_dict(),
                        "vt_score": first_rows["t_gen"]["score"],
                        "ci_low": gen[1],
                        "ci_high": gen[2],
                    }
                )
                + " "
                + claims.ridge_verdict(vs_ridge, pairing, float(first_rows["t_gen"]["pairing_p"])),
                "page": category("Generation"),
            }
        )
    return pd.DataFrame(rows, columns=FINDINGS_COLUMNS)


def _success(r: Mapping) -> str:
    # claims' function, not report.policy's wrapper: that module pulls in MuJoCo (2 s of imports)
    return claims.proportion_with_ci(r["success"], r["ci_low"], r["ci_high"], int(r["n_episodes"]))


def policy_findings(
    summary: pd.DataFrame, deltas: pd.DataFrame, sweep: pd.DataFrame
) -> pd.DataFrame:
    """V+T (aligned) against V on the same held-out episodes with the null-touch control, and
    the V-only policy against the vision-only ceiling."""
    d = deltas.set_index("condition")
    s = summary.drop_duplicates("condition").set_index("condition")
    rows = []
    if "vt_aligned" in d.index and "v" in s.index:
        r, v, vt = d.loc["vt_aligned"], s.loc["v"], s.loc["vt_aligned"]
        null = d.loc["vt_null"] if "vt_null" in d.index else None
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
    return pd.DataFrame(rows, columns=FINDINGS_COLUMNS)


def backbone_findings(
    summary: pd.DataFrame, main: Sequence[str], order: Sequence[str] = ()
) -> pd.DataFrame:
    """One row per backbone family other than the main DAG's (whose rows are the probes
    stage's, already on this page): V+T − V under the linear probe on each real-corpus probe
    family, the null corpus's probe families of the same targets as the control, and the
    verdict of the family's sentence (`report.backbones.direction_holds`, `null_gains`).
    Families in `order` (config backbones.run), then any other."""
    rows = []
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
        verdict = (
            "The V+T direction holds: Δ > 0 on every real-corpus probe."
            if direction_holds(summary[summary["family"] == family])
            else "The V+T direction does not hold on every real-corpus probe."
        )
        above = null_gains(null)
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
    return pd.DataFrame(rows, columns=FINDINGS_COLUMNS)


def transfer_findings(summary: pd.DataFrame) -> pd.DataFrame:
    """One row for the transfer to a second sensor (`tacgen_lib.probes.transfer`): the seeds'
    mean Δ balanced accuracy with the first sensor's heads and with retrained heads, the null
    corpus's heads and shuffled touch as the controls, and the verdict on the transferred
    heads' Δ, whether it beats the shuffled control and whether it beats the floor."""
    means = summary[summary["probe_seed"] == "mean"].set_index("heads")
    if "source" not in means.index:
        return pd.DataFrame(columns=FINDINGS_COLUMNS)

    def delta(view: str, col: str = "delta") -> str:
        if view not in means.index:
            return "not run"
        x = means.loc[view]
        text = fmt.with_ci(x[col], x[f"{col}_ci_low"], x[f"{col}_ci_high"], sign=True)
        return (
            f"{text} ({int(x['positive_seeds'])}/{int(x['n_seeds'])} seeds > 0)"
            if (col == "delta")
            else text
        )

    src = means.loc["source"]
    verdict = claims.delta_verdict(src["delta"], src["delta_ci_low"], src["delta_ci_high"])
    if beats_shuffled_control(src["delta_ci_low"], src["delta_shuffled_ci_high"]):
        verdict += " It lies above the shuffled-touch control."
    else:
        verdict += " It does not separate from the shuffled-touch control."
    if "floor" in means.index:
        floor = means.loc["floor"]
        if src["delta_ci_low"] > floor["delta"]:
            verdict += " The transferred heads beat the null corpus's heads."
        else:
            verdict += (
                " The null corpus's heads do as well (Δ "
                f"{fmt.signed(floor['delta'])}): what touch adds here is not what alignment learnt."
            )
    return pd.DataFrame(
        [
            {
                "evidence": "transfer to a second sensor",
                "question": "do heads trained on one sensor make touch add to vision on unseen "
                f"objects of another? (mass tertiles, balanced accuracy, {int(src['n_test_objects'])} "
                f"test objects, mean of {int(src['n_seeds'])} probe seeds)",
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


def pixel_findings(summary: pd.DataFrame) -> pd.DataFrame:
    """One row per judged corpus for the pixel generators (`tacgen_lib.generate.pixel`): per
    target the best raw generator arm's Δ (first seed) against real touch at the generators'
    frame size, the shuffled pairing as the control, and the verdict: which arms are
    utility-positive (Δ CI above 0 and above the shuffled control's interval)."""
    from tacgen_lib.report.pixel import arm_label, utility_positive

    out = []
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
    return pd.DataFrame(out, columns=FINDINGS_COLUMNS)
