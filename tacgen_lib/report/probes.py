"""Tables of the probes stage, built from the probe summary (pure functions).

Input is the tidy summary written by rule ``aggregate_probes`` (one row per family, input,
tactile variant, fusion, alignment seed, probe seed and control; see `tacgen_lib.probes.protocol`), plus its
lambda/C sweep and confusion-count tables. Every function returns a DataFrame (rendered to
HTML with `report_tables.to_html`) or a matplotlib Figure; none reads or writes files.

- `controlled_table`: families on the appearance-controlled corpus (mass, log-mass, density;
  pixel-V headline and backbone-V sensitivity), V vs V+T for every input and fusion.
- `paired_table`: families on the paired corpus (hardness, force), each with its null-corpus
  sibling (family name + ``_null``) in the columns beside it.
- `sweep_table`: Delta at every lambda (test R^2, ridge) or C (CV accuracy, logistic) for
  each fusion variant; ``*`` marks the value CV chose for the V+T probe.
- `align_seed_table`: aligned-input results as mean +- sd over alignment seeds.
- `variant_table`: the tactile preprocessing ablation (raw V + raw T of each variant, concat).
- `controls_table`: every control row next to its comparison's Delta.

Its figures (forest plots, confusion matrices) are `tacgen_lib.report.probe_figures`'.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from tacgen_lib.probes.fusion import fusion_table
from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt
from tacgen_lib.report.tables import constants_to_lead, footnote_column

__all__ = [
    "SHARED_COLUMNS",
    "align_seed_table",
    "baselines_text",
    "comparison_page",
    "controlled_table",
    "controls_table",
    "headline_rows",
    "seed_text",
    "skipped_note",
    "fusions_frame",
    "main_rows",
    "paired_table",
    "sweep_table",
    "variant_table",
]

_ORDER = ["family", "input", "t_variant", "fusion", "align_seed", "probe_seed"]


def _num(x: object, spec: str = "{:.3f}") -> str:
    """`x` written by `tacgen_lib.report.format`: signed where `spec` has a sign, 4 decimals
    for p-values (`spec` "{:.4f}"), else 3."""
    if "+" in spec:
        return fmt.signed(x)
    return fmt.number(x, 4 if ".4f" in spec else 3)


def seed_text(x: object) -> str:
    if x is None or x is pd.NA or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return str(int(x))


def _delta_ci(row: pd.Series) -> str:
    if row.get("status", "ok") != "ok":
        return f"({row['status']})"
    return f"{_num(row['delta'], '{:+.3f}')} [{_num(row['ci_low'], '{:+.3f}')}, {_num(row['ci_high'], '{:+.3f}')}]"


def _criterion(x: object) -> str:
    if fmt.is_missing(x):
        return "not evaluated"
    return "yes" if bool(x) else "no"


def main_rows(summary: pd.DataFrame) -> pd.DataFrame:
    """The V vs V+T comparisons (control == "none"), in a stable order."""
    rows = summary.loc[summary["control"] == "none"].copy()
    rows["_a"] = rows["align_seed"].fillna(-1)
    return rows.sort_values(
        ["family", "input", "t_variant", "fusion", "_a", "probe_seed"], kind="stable"
    ).drop(columns="_a")


def headline_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """Main comparisons with the heads' tactile variant (the ablation has its own table)."""
    return rows.loc[rows["t_variant"] == rows["heads_variant"]]


def _col(rows: pd.DataFrame, name: str) -> pd.Series:
    """A column of the summary, or NaN for a summary written before it existed."""
    return rows[name] if name in rows else pd.Series(math.nan, index=rows.index)


def baselines_text(r: pd.Series) -> str:
    """V, V+T and the baselines that size a Delta, as one short text."""
    text = f"V {_num(r['v_score'])}  V+T {_num(r['vt_score'])}"
    text += f"  mean {_num(r.get('baseline_score', math.nan))}"
    shape = _num(r.get("visible_score", math.nan))
    return text + (f"  shape {shape}" if shape else "")


def _comparison_columns(rows: pd.DataFrame) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "family": rows["family"],
            "target": rows["target"],
            "V features": rows.get("vision", pd.Series("", index=rows.index)),
            "input": rows["input"],
            "fusion": rows["fusion"],
            "align seed": rows["align_seed"].map(seed_text),
            "probe seed": rows["probe_seed"].map(seed_text),
            "metric": rows["metric"],
            "V": rows["v_score"].map(_num),
            "V+T": rows["vt_score"].map(_num),
            "train mean / shape-only": [
                f"{_num(m)} / {_num(s)}"
                for m, s in zip(
                    _col(rows, "baseline_score"), _col(rows, "visible_score"), strict=True
                )
            ],
            "Δ [95% CI]": rows.apply(_delta_ci, axis=1),
            "p(Δ>0)": rows["p_gt0"].map(_num),
            "Δ_ctrl": rows["delta_ctrl"].map(lambda x: _num(x, "{:+.3f}")),
            "criterion (paper / Holm, family)": [
                _criteria(a, b)
                for a, b in zip(
                    rows["criterion_met"], _col(rows, "criterion_adjusted"), strict=True
                )
            ],
            "p Holm (family) / q BH (all)": [
                _p_pair(p, q)
                for p, q in zip(_col(rows, "p_holm_family"), _col(rows, "p_bh"), strict=True)
            ],
            "n train/test": rows["n_train"].astype(str) + "/" + rows["n_test"].astype(str),
            # a row's warning and notes, one text (the page writes it as a footnote mark)
            "notes": [
                "; ".join(t for t in (_flag(r), r.notes if isinstance(r.notes, str) else "") if t)
                for r in rows.itertuples()
            ],
        }
    ).reset_index(drop=True)


def _criteria(paper: object, holm: object) -> str:
    """The paper's criterion and its Holm-adjusted reading, as one cell ("yes / no"); "not
    evaluated" once where neither was."""
    a, b = _criterion(paper), _criterion(holm)
    return a if a == b == "not evaluated" else f"{a} / {b}"


def _p_pair(p: float, q: float) -> str:
    """A row's family-wise Holm p and its all-comparisons BH q, as one cell ("p / q"); a
    row without them (a summary from before they existed) gets the missing mark."""
    if not (np.isfinite(p) or np.isfinite(q)):
        return fmt.MISSING
    return f"{_num(p, '{:.4f}')} / {_num(q, '{:.4f}')}"


def _flag(r) -> str:
    """The warning `claims.extreme_flag` gives a comparison row, or ""."""
    return claims.extreme_flag(
        r.metric,
        r.v_score,
        r.vt_score,
        r.ci_low,
        r.ci_high,
        getattr(r, "baseline_score", math.nan),
        getattr(r, "n_test", math.nan),
    )


#: the comparison tables' columns stated once above the table where every row shares a value
SHARED_COLUMNS = ("V features", "probe seed", "n train/test")


def comparison_page(table: pd.DataFrame) -> tuple[pd.DataFrame, list[str], list[str]]:
    """A comparison table (`controlled_table`, `paired_table`) as its page shows it, narrow
    enough for its frame: (the table, the lead stating the `SHARED_COLUMNS` every row shares,
    the footnotes its "notes" column's marks point to)."""
    table, lead = constants_to_lead(table, SHARED_COLUMNS)
    table, marks = footnote_column(table, "notes")
    return table, lead, marks


def skipped_note(summary: pd.DataFrame, controlled: bool) -> list[str]:
    """One footnote for the comparisons planned as skipped on a corpus design (they are left
    out of its table): how many, and each distinct reason once."""
    rows = headline_rows(main_rows(summary))
    rows = rows.loc[
        ((rows["design"] == "controlled") == controlled) & (rows["status"] == "skipped")
    ]
    if not len(rows):
        return []
    reasons = "; ".join(dict.fromkeys(str(n) for n in rows["notes"] if n))
    fusions = ", ".join(sorted(set(rows["fusion"])))
    s = "" if len(rows) == 1 else "s"
    return [f"{len(rows)} comparison{s} not run and not listed ({fusions}): {reasons}"]


def controlled_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Families on the appearance-controlled corpus: pixel-V families first (the headline).
    Comparisons planned as skipped are left out (`skipped_note` says which and why)."""
    rows = headline_rows(main_rows(summary))
    rows = rows.loc[(rows["design"] == "controlled") & (rows["status"] != "skipped")].copy()
    rows["_vit"] = rows["vision"] != "pixel"
    rows = rows.sort_values(["_vit", "family"], kind="stable")
    return _comparison_columns(rows)


def _keys(rows: pd.DataFrame, columns: list[str]) -> list[str]:
    """One text key per row from `columns` (missing values as "-")."""
    return [
        "|".join(
            seed_text(v)
            if isinstance(v, (int, float, np.integer)) or v is pd.NA or v is None
            else str(v)
            for v in r
        )
        for r in rows[columns].itertuples(index=False)
    ]


def paired_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Paired-corpus families, each with its ``_null`` sibling's result in the columns beside;
    comparisons planned as skipped are left out (`skipped_note`)."""
    rows = headline_rows(main_rows(summary))
    rows = rows.loc[(rows["design"] != "controlled") & (rows["status"] != "skipped")]
    families = sorted(rows["family"].unique())
    main = [f for f in families if not (f.endswith("_null") and f[: -len("_null")] in families)]
    key = ["input", "fusion", "align_seed", "probe_seed"]
    out = []
    for fam in main:
        a = rows.loc[rows["family"] == fam].copy()
        table = _comparison_columns(a)
        null = rows.loc[rows["family"] == f"{fam}_null"]
        if len(null):
            a["_k"] = _keys(a, key)
            null = null.assign(_k=_keys(null, key))
            by_key = null.set_index("_k")
            got = [by_key.loc[k] if k in by_key.index else None for k in a["_k"]]
            table["null: V+T"] = [_num(g["vt_score"]) if g is not None else "" for g in got]
            table["null: Δ [95% CI]"] = [_delta_ci(g) if g is not None else "" for g in got]
            table["null: criterion"] = [
                _criterion(g["criterion_met"]) if g is not None else "" for g in got
            ]
        out.append(table)
    return pd.concat(out, ignore_index=True) if out else pd.DataFrame()


def sweep_table(sweep: pd.DataFrame, summary: pd.DataFrame) -> pd.DataFrame:
    """One row per comparison, one column per lambda / C: Delta at that regulariser.

    Ridge: Delta of test R^2 with both probes refitted at that lambda. Logistic: Delta of the
    mean CV accuracy (no test refit per C). ``*`` marks the regulariser CV chose for V+T.
    """
    if sweep.empty:
        return pd.DataFrame()
    heads = summary.drop_duplicates("family").set_index("family")["heads_variant"]
    sw = sweep.loc[sweep["t_variant"].to_numpy() == sweep["family"].map(heads).to_numpy()].copy()
    sw["value"] = np.where(
        sw["reg_name"] == "lambda", sw["test_vt"] - sw["test_v"], sw["cv_vt"] - sw["cv_v"]
    )
    sw["cell"] = [
        f"{v:+.3f}{'*' if s else ''}" for v, s in zip(sw["value"], sw["selected_vt"], strict=True)
    ]
    sw["_a"] = sw["align_seed"].map(seed_text)
    sw["column"] = sw["reg_name"] + "=" + sw["reg"].map(lambda r: f"{r:g}")
    sw["measure"] = np.where(sw["reg_name"] == "lambda", "Δ test R²", "Δ CV accuracy")
    index = ["family", "measure", "input", "fusion", "_a", "probe_seed"]
    table = sw.pivot_table(index=index, columns="column", values="cell", aggfunc="first")
    cols = sorted(table.columns, key=lambda c: (c.split("=")[0], float(c.split("=")[1])))
    table = table[cols].fillna("").reset_index().rename(columns={"_a": "align seed"})
    table.columns.name = None
    return table


def align_seed_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Aligned-input comparisons aggregated over alignment seeds: mean +- sd, criterion count."""
    rows = main_rows(summary)
    rows = rows.loc[(rows["input"] == "aligned") & (rows["status"] == "ok")]
    out = []
    for (fam, fusion, seed), g in rows.groupby(["family", "fusion", "probe_seed"], sort=True):

        def ms(col: str, g: pd.DataFrame = g) -> str:
            x = g[col].astype(float).to_numpy()
            sd = float(np.std(x, ddof=1)) if x.size > 1 else 0.0
            return f"{x.mean():+.3f} ± {sd:.3f}" if col == "delta" else f"{x.mean():.3f} ± {sd:.3f}"

        met = g["criterion_met"].dropna()
        out.append(
            {
                "family": fam,
                "target": g["target"].iloc[0],
                "fusion": fusion,
                "probe seed": int(seed),
                "align seeds": ", ".join(map(seed_text, g["align_seed"])),
                "V": ms("v_score"),
                "V+T": ms("vt_score"),
                "Δ": ms("delta"),
                "CI low > 0": f"{int((g['ci_low'] > 0).sum())}/{len(g)}",
                "criterion met": f"{int(met.astype(bool).sum())}/{len(met)}" if len(met) else "n/a",
            }
        )
    return pd.DataFrame(out)


def variant_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Tactile preprocessing ablation: raw V + raw T (concat) for every variant and family."""
    rows = main_rows(summary)
    rows = rows.loc[(rows["input"] == "raw") & (rows["fusion"] == "concat")].copy()
    if rows.empty:
        return pd.DataFrame()
    rows["cell"] = rows.apply(lambda r: f"{_num(r['vt_score'])} (Δ {_delta_ci(r)})", axis=1)
    table = rows.pivot_table(
        index=["family", "target", "metric", "probe_seed"],
        columns="t_variant",
        values="cell",
        aggfunc="first",
    )
    v = rows.groupby(["family", "target", "metric", "probe_seed"])["v_score"].first().map(_num)
    table.insert(0, "V alone", v)
    table = table.reset_index().rename(columns={"probe_seed": "probe seed"})
    table.columns.name = None
    return table


def controls_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Each control's Delta distribution beside the Delta of the comparison it controls."""
    ctrl = summary.loc[summary["control"] != "none"]
    if ctrl.empty:
        return pd.DataFrame()
    main = main_rows(summary).set_index("row_id")
    parent = ctrl["row_id"].str.rsplit("|", n=1).str[0] + "|none"
    ctrl = ctrl.assign(_a=ctrl["align_seed"].fillna(-1)).sort_values(
        ["family", "input", "_a", "probe_seed", "control"], kind="stable"
    )
    parent = parent.loc[ctrl.index]
    return pd.DataFrame(
        {
            "family": ctrl["family"],
            "input": ctrl["input"],
            "fusion": ctrl["fusion"],
            "align seed": ctrl["align_seed"].map(seed_text),
            "probe seed": ctrl["probe_seed"].map(seed_text),
            "Δ (comparison)": [_num(main.loc[p, "delta"], "{:+.3f}") for p in parent],
            "control": ctrl["control"],
            "draws": ctrl["n_resamples"].astype(str),
            "V": ctrl["v_score"].map(_num),
            "V+T (mean)": ctrl["vt_score"].map(_num),
            "Δ mean [2.5%, 97.5%]": [
                f"{d:+.3f} [{lo:+.3f}, {hi:+.3f}]"
                for d, lo, hi in zip(ctrl["delta"], ctrl["ci_low"], ctrl["ci_high"], strict=True)
            ],
            "p(Δ>0)": ctrl["p_gt0"].map(_num),
            "notes": ctrl["notes"],
        }
    ).reset_index(drop=True)


def fusions_frame() -> pd.DataFrame:
    """The fusion variants (`fusion.fusion_table`) as a table."""
    return pd.DataFrame(fusion_table())
