"""The findings page's rows of the probes and generation branches (`tacgen_lib.report.findings`
gathers every branch's): per probe family and input, V+T against V with the controls and the
criterion (`probe_findings`); per generator corpus and target, generated touch against real
touch with the shuffled-pair control, the nonlinear V-only baseline and ridge V->T
(`generation_findings`). Each returns its rows and the decisions their verdicts state
(`tacgen_lib.report.decisions`). Pure functions over the stages' summary edges.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt
from tacgen_lib.report.decisions import FindingsPart, decision, side_decision
from tacgen_lib.report.generate import cross_seed_interval, delta_with_ci, reference_cell_rows
from tacgen_lib.report_pages import FINDINGS_COLUMNS, category

__all__ = ["generation_findings", "probe_findings"]


def _input_label(r: Mapping, seeds: Sequence[int]) -> str:
    if r["input"] == "aligned":
        which = ", ".join(str(int(x)) for x in seeds) or str(int(r["align_seed"]))
        return f"aligned heads (seed{'s' if len(seeds) > 1 else ''} {which})"
    return "raw features"


def _flag(r: Mapping) -> str:
    flag = claims.extreme_flag(
        r["metric"],
        r["v_score"],
        r["vt_score"],
        r["ci_low"],
        r["ci_high"],
        r.get("baseline_score", np.nan),
        r.get("n_test", np.nan),
    )
    return f" ⚠ {flag}." if flag else ""


def _majority_decision(decision_id: str, evidence: str, where: str, r: Mapping) -> list[dict]:
    """The decision behind the "V below the majority-class rate" flag of an accuracy row."""
    if r.get("metric") != "accuracy" or fmt.is_missing(r.get("baseline_score", np.nan)):
        return []
    below = claims.below_majority(r["v_score"], r["baseline_score"], r.get("n_test", np.nan))
    return [
        decision(
            f"{decision_id}|v_vs_majority",
            evidence,
            f"V accuracy against the majority-class rate ({where})",
            "below majority" if below else "not below majority",
            value=r["v_score"],
            threshold=r["baseline_score"],
        )
    ]


def _headline_probe_rows(summary: pd.DataFrame) -> pd.DataFrame:
    """The probe summary's main comparisons that make a findings row: concat fusion, the
    heads' tactile variant, run without error."""
    return summary[
        (summary["control"] == "none")
        & (summary["fusion"] == "concat")
        & (summary["t_variant"] == summary["heads_variant"])
        & (summary["status"] == "ok")
    ]


def probe_findings(summary: pd.DataFrame) -> FindingsPart:
    """Per probe family and input, the headline comparison (concat fusion, the heads' tactile
    variant, controls run), with its controls' largest Δ. Aligned rows exist once per
    alignment seed: the row reads them together (`claims.seeds_interval`: the mean over the
    seeds, an interval holding each seed's CI and the seeds' spread), so its decision does not
    rest on one training of the heads; the controls and the criterion are the first seed's
    with controls run."""
    headline = _headline_probe_rows(summary)
    s = headline[headline["delta_ctrl"].notna()].copy()
    s["_a"] = s["align_seed"].fillna(-1)
    s = s.sort_values(["null_corpus", "family", "input", "_a"], kind="stable")
    s = s.drop_duplicates(["family", "input"], keep="first")
    rows, decided = [], []
    for r in s.to_dict("records"):
        null = bool(r["null_corpus"])
        seeds = pd.DataFrame([r])
        if r["input"] == "aligned":  # every heads seed of this probe seed
            seeds = headline[
                (headline["family"] == r["family"])
                & (headline["input"] == "aligned")
                & (headline["probe_seed"] == r["probe_seed"])
                & (headline.get("protocol", "raw") == r.get("protocol", "raw"))
                & headline["align_seed"].notna()
            ].sort_values("align_seed", kind="stable")
        delta, lo, hi = claims.seeds_interval(seeds["delta"], seeds["ci_low"], seeds["ci_high"])
        per_seed = (
            "; per seed "
            + ", ".join(
                f"{int(x.align_seed)}: {fmt.with_ci(x.delta, x.ci_low, x.ci_high, sign=True)}"
                for x in seeds.itertuples()
            )
            if len(seeds) > 1
            else ""
        )
        seed_list = [int(x) for x in seeds["align_seed"].dropna()]
        where = f"{r['corpus']}, {_input_label(r, seed_list)}, {r['metric']}"
        did = f"probe|{r['family']}|{r['input']}"
        decided.append(
            decision(
                did,
                "probe",
                f"V+T − V on {r['target']} ({where})",
                side_decision(lo, hi),
                value=delta,
                ci_low=lo,
                ci_high=hi,
                threshold=0.0,
            )
        )
        criterion = None if fmt.is_missing(r["criterion_met"]) else bool(r["criterion_met"])
        if criterion is not None and not null:
            decided.append(
                decision(
                    f"{did}|criterion",
                    "probe",
                    f"the paper's criterion (Δ ≥ 0.03, CI above 0, Δ_ctrl "
                    f"{fmt.signed(r['delta_ctrl'])} < Δ; {where})",
                    "met" if criterion and claims.interval_side(lo, hi) == "above" else "not met",
                    value=delta,
                    threshold=0.03,
                )
            )
        decided += _majority_decision(did, "probe", where, r)
        mean_note = (
            f" (mean over {len(seeds)} heads seeds; the interval holds each seed's CI)"
            if len(seeds) > 1
            else ""
        )
        rows.append(
            {
                "evidence": "probe",
                "question": f"{r['family']}: does touch add to vision on {r['target']}? ({where})",
                "result": f"V {fmt.number(r['v_score'])} → V+T {fmt.number(r['vt_score'])}; "
                f"Δ {fmt.with_ci(delta, lo, hi, sign=True)}{mean_note}{per_seed}",
                "control": f"touch permuted across rows: Δ_ctrl {fmt.signed(r['delta_ctrl'])}"
                + ("; null corpus: touch carries no label" if null else ""),
                "verdict": claims.probe_verdict(
                    delta,
                    lo,
                    hi,
                    null_corpus=null,
                    criterion_met=criterion,
                    delta_ctrl=r["delta_ctrl"],
                )
                + _flag(r),
                "page": category("Probes"),
            }
        )
    return FindingsPart(pd.DataFrame(rows, columns=FINDINGS_COLUMNS), decided)


def _first_seed(rows: pd.DataFrame, col: str = "delta") -> tuple[float, float, float]:
    """(Δ, lo, hi) of the first generator seed with its fixed-test bootstrap CI."""
    if rows is None or not len(rows):
        return (np.nan, np.nan, np.nan)
    return delta_with_ci(_first_row(rows), col)


def _first_row(rows: pd.DataFrame) -> pd.Series:
    """The first generator seed's row."""
    return rows.sort_values("seed", kind="stable").iloc[0]


def _gap_intervals(row: Mapping) -> dict[str, tuple[float, float, float]]:
    """The t_gen row's pairing-gap differences from ridge's arms with their intervals
    (`generate.evaluate.pairing_gap_columns`); empty for an edge without them."""
    out = {}
    for arm in ("ridge", "ridge_residual"):
        cols = (f"gap_vs_{arm}", f"gap_vs_{arm}_ci_low", f"gap_vs_{arm}_ci_high")
        if all(c in row and not fmt.is_missing(row[c]) for c in cols):
            out[arm] = tuple(float(row[c]) for c in cols)
    return out if len(out) == 2 else {}


def _fw(row: Mapping, col: str = "delta") -> tuple[float, float, float]:
    """(Δ, lo, hi) of a generated row with its family-wise interval (`ci_low_fw`, or
    `ci_low_fw_vs_ridge` for `col` delta_vs_ridge), the Generation page's reading of the
    cells it compares; its 95 % CI where the edge has none."""
    suffix = col.removeprefix("delta")
    lo, hi = row.get(f"ci_low_fw{suffix}"), row.get(f"ci_high_fw{suffix}")
    if lo is None or fmt.is_missing(lo):
        return delta_with_ci(row, col)
    return float(row[col]), float(lo), float(hi)


def _fw_over_seeds(rows: pd.DataFrame, col: str = "delta") -> tuple[float, float, float]:
    """`_fw` of every generator seed's row read as one (`claims.seeds_interval`: each seed's
    family-wise interval and, from three seeds on, the mean's t-interval): the generator's
    training draw is a replicate, so a decision holds whichever seeds were drawn."""
    reads = [_fw(r, col) for _, r in rows.sort_values("seed", kind="stable").iterrows()]
    return claims.seeds_interval(*zip(*reads, strict=True))


def _generation_decisions(
    did: str,
    where: str,
    gen,
    real,
    nonlin,
    vs_ridge,
    pairing,
    pairing_p: float,
    first: Mapping,
    gaps: Mapping,
) -> list[dict]:
    """The decisions of a generation row: Δ_gen and Δ_real against 0, whether the nonlinear
    V-only probe explains a gain, generated against ridge V→T in the probe, and the pairing
    of the samples with real touch (`claims.pairing_decision`)."""
    out = [
        decision(
            f"{did}|{name}",
            "generation",
            f"{what} ({where})",
            side_decision(x[1], x[2]),
            value=x[0],
            ci_low=x[1],
            ci_high=x[2],
            threshold=0.0,
        )
        for name, what, x in (
            ("t_gen", "V + T_gen − V", gen),
            ("t_real", "V + T_real − V", real),
            ("v_nonlinear", "V + φ(V) − V, the nonlinear V-only baseline", nonlin),
            ("vs_ridge", "V + T_gen − (V + ridge V→T)", vs_ridge),
        )
    ]
    out.append(
        decision(
            f"{did}|pairing",
            "generation",
            f"pairing of the generated samples with real touch ({where})",
            claims.pairing_decision(pairing, pairing_p, gaps),
            value=pairing_p,
            threshold=claims.PAIRING_P,
        )
    )
    out += _majority_decision(did, "generation", where, first)
    return out


def generation_findings(summary: pd.DataFrame, ref: Mapping) -> FindingsPart:
    """Per corpus × target at the reference sampling cell: generated touch against real touch,
    with the shuffled-pair control, the nonlinear V-only baseline and the ridge V->T generator.

    The verdict reads fixed-test bootstrap intervals (they carry the test rows' sampling
    noise; real touch and the baselines do not depend on the generator seed: the first
    seed's), those of generated touch (Δ_gen, the shuffled control, Δ_gen − ridge)
    family-wise, as the Generation page reads every generated row it compares (`_fw`: an
    interval one cell of many would clear by chance is not a finding), over every generator
    seed (`_fw_over_seeds`: one generator's training decides nothing another seed's would
    reverse); the pairing of the samples is the first seed's. The mean over seeds with its
    t-interval, which carries only the seeds' spread, is shown beside."""
    s = reference_cell_rows(summary, ref)
    rows, decided = [], []
    for (corpus, target), g in s.groupby(["corpus", "target"], sort=True):
        by = {k: v for k, v in g.groupby("input")}
        if not {"t_gen", "t_real"} <= set(by):
            continue
        first_rows = {k: _first_row(by[k]) for k in ("t_gen", "t_ridge", "t_ridge_residual")}
        gen, real = _fw_over_seeds(by["t_gen"]), _first_seed(by["t_real"])
        shuffled = (
            _fw_over_seeds(by["t_gen_shuffled"])
            if "t_gen_shuffled" in by
            else (np.nan, np.nan, np.nan)
        )
        nonlin = _first_seed(by.get("v_nonlinear"))
        ridge = _fw(first_rows["t_ridge"])
        vs_ridge = _fw_over_seeds(by["t_gen"], "delta_vs_ridge")
        pairing = {
            k: (float(r["cos_matched"]), float(r["cos_offdiag"])) for k, r in first_rows.items()
        }
        seeds = cross_seed_interval(by["t_gen"]["delta"].to_numpy())
        n = int(g["seed"].nunique())
        first = int(g["seed"].min())
        metric = g["metric"].iloc[0]
        pairing_p = float(first_rows["t_gen"]["pairing_p"])
        gaps = _gap_intervals(first_rows["t_gen"])
        flagged = {
            **first_rows["t_gen"].to_dict(),
            "vt_score": first_rows["t_gen"]["score"],
            "ci_low": gen[1],
            "ci_high": gen[2],
        }
        decided += _generation_decisions(
            f"generation|{corpus}|{target}",
            f"{corpus}, {target}, {metric}",
            gen,
            real,
            nonlin,
            vs_ridge,
            pairing,
            pairing_p,
            flagged,
            gaps,
        )
        rows.append(
            {
                "evidence": "generation",
                "question": f"does touch generated from RGB add to vision on {target}? "
                f"({corpus}, {metric})",
                "result": f"Δ_gen {fmt.with_ci(*gen, sign=True)} ("
                + (f"seed {first}" if n == 1 else f"{n} generator seeds read as one")
                + "; generated rows with their family-wise intervals"
                + (f"; mean over {n} seeds {fmt.with_ci(*seeds, sign=True)}" if n > 1 else "")
                + f"); Δ_real {fmt.with_ci(*real, sign=True)}",
                "control": f"shuffled pairs Δ {fmt.with_ci(*shuffled, sign=True)}; nonlinear "
                f"V only Δ {fmt.with_ci(*nonlin, sign=True)}; ridge V→T generator Δ "
                f"{fmt.with_ci(*ridge, sign=True)}",
                "verdict": claims.generation_verdict(gen, real, nonlin)
                + _flag(flagged)
                + " "
                + claims.ridge_verdict(vs_ridge, pairing, pairing_p, gaps),
                "page": category("Generation"),
            }
        )
    return FindingsPart(pd.DataFrame(rows, columns=FINDINGS_COLUMNS), decided)
