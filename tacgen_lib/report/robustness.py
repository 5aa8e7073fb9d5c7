"""The report's Robustness section: do the headline probe results survive a change of protocol?

Built from the probe summary (every protocol variant's rows, with `probes.multiplicity`'s
columns), the training-size sweep and the within-scale diagnosis. Pure functions: frames in,
frames or a Figure out.

- `headline_long`: the headline comparisons (``concat`` with the heads' tactile variant, raw and
  aligned inputs) under every protocol, one row each; a logistic family's ``standardised``
  row is its ``raw`` row (`protocol_variants.same_as_raw`), marked so.
- `robustness_table` + `survival_sentence`: family x input x protocol Delta [95% CI], and a
  sentence generated from it saying which results have a CI above 0 under every protocol.
- `multiplicity_table`: CIs excluding 0, Holm / BH rejections, chance expectation.
- `within_scale_table`: held-out-scale result beside the within-scale result, per protocol.
- `training_size_table` / `training_size_figure`: Delta against n_train with CIs.
"""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import NullFormatter

from tacgen_lib.probes.protocol_variants import same_as_raw
from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt
from tacgen_lib.report.write import panel_grid

__all__ = [
    "headline_long",
    "multiplicity_table",
    "robustness_table",
    "survival_sentence",
    "training_size_figure",
    "training_size_table",
    "within_scale_table",
]

LONG_COLUMNS = (
    "row_id",
    "family",
    "corpus",
    "target",
    "metric",
    "null_corpus",
    "input",
    "align_seed",
    "probe_seed",
    "protocol",
    "same_as_raw",
    "v_score",
    "vt_score",
    "delta",
    "ci_low",
    "ci_high",
    "p_boot",
    "status",
    "notes",
)


def _fmt(x: object, spec: str = "{:+.3f}") -> str:
    """`x` written by `tacgen_lib.report.format` (signed where `spec` has a sign)."""
    return fmt.signed(x) if "+" in spec else fmt.number(x)


def _ci(d: float, lo: float, hi: float) -> str:
    return fmt.with_ci(d, lo, hi, sign=True)


def _input(r: pd.Series) -> str:
    a = r["align_seed"]
    return "raw" if r["input"] == "raw" else f"aligned a~{int(a)}"


def headline_long(
    summary: pd.DataFrame, families: Sequence[str], protocols: Sequence[str]
) -> pd.DataFrame:
    """Headline comparisons of `families` under every protocol in `protocols` (long form)."""
    rows = summary.loc[
        (summary["control"] == "none")
        & (summary["fusion"] == "concat")
        & (summary["t_variant"] == summary["heads_variant"])
        & summary["family"].isin(families)
    ].copy()
    if "protocol" not in rows:
        rows["protocol"] = "raw"
    out = []
    for _, r in rows.iterrows():
        if r["protocol"] not in protocols:
            continue
        out.append({**r.to_dict(), "same_as_raw": False})
        if r["protocol"] == "raw":
            for p in protocols:
                if same_as_raw(p, r["kind"]):
                    out.append(
                        {
                            **r.to_dict(),
                            "protocol": p,
                            "same_as_raw": True,
                            "row_id": r["row_id"].replace("|none", f"|p~{p}|none"),
                        }
                    )
    frame = pd.DataFrame(out)
    if frame.empty:
        return pd.DataFrame(columns=list(LONG_COLUMNS))
    for col in ("p_boot",):
        if col not in frame:
            frame[col] = np.nan
    frame = frame[list(LONG_COLUMNS)].copy()
    frame["notes"] = frame["notes"].fillna("").astype(str)
    frame["null_corpus"] = frame["null_corpus"].astype(bool)
    frame["same_as_raw"] = frame["same_as_raw"].astype(bool)
    return frame.sort_values("row_id", ignore_index=True)


def _order(frame: pd.DataFrame, families: Sequence[str]) -> pd.DataFrame:
    """Families in config order, raw input before aligned, then alignment and probe seed."""
    rank = {f: i for i, f in enumerate(families)}
    return frame.assign(
        _f=frame["family"].map(rank),
        _r=frame["_input"] != "raw",
        _a=frame["align_seed"].fillna(-1),
    ).sort_values(["_f", "_r", "_a", "probe seed"], kind="stable")


def robustness_table(
    long: pd.DataFrame, families: Sequence[str], protocols: Sequence[str]
) -> pd.DataFrame:
    """Family x input x probe seed rows, one "Δ [95% CI]" column per protocol, and whether
    the CI lies above 0 under every protocol."""
    out = []
    groups = long.assign(_a=long["align_seed"].fillna(-1)).groupby(
        ["family", "input", "_a", "probe_seed"], sort=False
    )
    for _, g in groups:
        r0 = g.iloc[0]
        row = {
            "family": r0["family"],
            "corpus": r0["corpus"],
            "metric": r0["metric"],
            "input": _input(r0),
            "probe seed": int(r0["probe_seed"]),
            "align_seed": r0["align_seed"],
            "_input": r0["input"],
        }
        above = []
        for p in protocols:
            hit = g.loc[g["protocol"] == p]
            if hit.empty:
                row[p] = "(not run)"
                above.append(None)
                continue
            h = hit.iloc[0]
            if h["status"] != "ok":
                row[p] = f"({h['status']})"
                above.append(False)
                continue
            flag = claims.extreme_flag(
                h["metric"], h["v_score"], h["vt_score"], h["ci_low"], h["ci_high"]
            )
            row[p] = (
                _ci(h["delta"], h["ci_low"], h["ci_high"])
                + (" (= raw)" if h["same_as_raw"] else "")
                + (f" ⚠ {flag}" if flag else "")
            )
            above.append(bool(h["ci_low"] > 0))
        ran = [a for a in above if a is not None]
        row["CI > 0 under every protocol"] = "yes" if ran and all(ran) else ("no" if ran else "n/a")
        row["CI > 0 under"] = ", ".join(p for p, a in zip(protocols, above, strict=True) if a)
        out.append(row)
    table = pd.DataFrame(out)
    if table.empty:
        return table
    table = _order(table, families)
    return table.drop(columns=["_f", "_r", "_a", "align_seed", "_input"]).reset_index(drop=True)


def survival_sentence(table: pd.DataFrame, null_families: Sequence[str]) -> str:
    """One generated sentence: which headline results (raw input) keep a CI above 0 under every
    protocol, which do not (and under which they do), and what the null rows do."""
    if table.empty:
        return "No headline comparison ran under the protocol variants."
    raw = table.loc[table["input"] == "raw"]
    main = raw.loc[~raw["family"].isin(null_families)]
    null = raw.loc[raw["family"].isin(null_families)]

    def names(part: pd.DataFrame) -> list[str]:
        return sorted(set(part["family"]))

    keep = main.groupby("family")["CI > 0 under every protocol"].apply(lambda s: (s == "yes").all())
    survive = sorted(keep.index[keep])
    fail = sorted(keep.index[~keep])
    parts = [
        "Raw-feature headline results with a 95% CI above 0 under every protocol variant: "
        + (", ".join(survive) if survive else "none")
        + "."
    ]
    if fail:
        detail = []
        for fam in fail:
            under = main.loc[main["family"] == fam, "CI > 0 under"].iloc[0]
            detail.append(f"{fam} (CI above 0 under: {under or 'none'})")
        parts.append("Not under every variant: " + "; ".join(detail) + ".")
    if len(null):
        any_above = null.loc[null["CI > 0 under"] != "", "family"]
        parts.append(
            "Null-corpus rows with a CI above 0 under some variant: "
            + (", ".join(sorted(set(any_above))) if len(any_above) else "none")
            + f" (of {', '.join(names(null))})."
        )
    return " ".join(parts)


def multiplicity_table(counts: pd.DataFrame) -> pd.DataFrame:
    """`multiplicity.ci_counts` for the report (null corpora marked)."""
    if counts.empty:
        return counts
    return pd.DataFrame(
        {
            "protocol": counts["protocol"],
            "family": counts["family"] + np.where(counts["null_corpus"], " (null)", ""),
            "comparisons": counts["comparisons"],
            "CI excludes 0 (above / below)": [
                f"{t} ({a} / {b})"
                for t, a, b in zip(
                    counts["ci_excludes_0"], counts["ci_above_0"], counts["ci_below_0"], strict=True
                )
            ],
            "expected by chance (5%)": counts["expected_by_chance"].map(lambda x: f"{x:.1f}"),
            "Holm p < 0.025": counts["holm_rejections"],
            "BH q < 0.025": counts["bh_rejections"],
            "criterion (paper)": counts["criterion_met"],
            "criterion (Holm, family)": counts["criterion_adjusted"],
        }
    )


def within_scale_table(long: pd.DataFrame, within: pd.DataFrame) -> pd.DataFrame:
    """Per family and protocol: the held-out-scale result (raw V vs V+T, concat) beside the
    same probe on the within-scale split."""
    if within.empty:
        return pd.DataFrame()
    out = []
    main = within.loc[(within["control"] == "none")]
    for _, w in main.sort_values(["family", "protocol"], kind="stable").iterrows():
        held = long.loc[
            (long["family"] == w["family"])
            & (long["protocol"] == w["protocol"])
            & (long["input"] == "raw")
        ]
        h = held.iloc[0] if len(held) else None
        out.append(
            {
                "family": w["family"],
                "protocol": w["protocol"],
                "held-out scale: V / V+T": ""
                if h is None
                else f"{_fmt(h['v_score'], '{:.3f}')} / {_fmt(h['vt_score'], '{:.3f}')}",
                "held-out scale: Δ [95% CI]": "(not run)"
                if h is None
                else _ci(h["delta"], h["ci_low"], h["ci_high"]),
                "within scale: V / V+T": f"{_fmt(w['v_score'], '{:.3f}')} / "
                f"{_fmt(w['vt_score'], '{:.3f}')}",
                "within scale: Δ [95% CI]": _ci(w["delta"], w["ci_low"], w["ci_high"]),
                "n train/test (within scale)": f"{w['n_train']}/{w['n_test']}",
            }
        )
    return pd.DataFrame(out)


def training_size_table(size: pd.DataFrame) -> pd.DataFrame:
    """Per family and n: Delta [95% CI] of each subset seed, and the mean over seeds."""
    if size.empty:
        return pd.DataFrame()
    out = []
    for (fam, n), g in size.groupby(["family", "n_train"], sort=True):
        ok = g.loc[g["status"] == "ok"]
        out.append(
            {
                "family": fam + (" (null)" if bool(g["null_corpus"].iloc[0]) else ""),
                "metric": g["metric"].iloc[0],
                "n train": int(n),
                "seeds": len(g),
                "Δ mean over seeds": _fmt(ok["delta"].mean()) if len(ok) else "",
                "CI above 0": f"{int((ok['ci_low'] > 0).sum())}/{len(g)}",
                "Δ [95% CI] per seed": "; ".join(
                    f"s~{int(r['subset_seed'])}: "
                    + (
                        _ci(r["delta"], r["ci_low"], r["ci_high"])
                        if r["status"] == "ok"
                        else f"({r['status']})"
                    )
                    for _, r in g.iterrows()
                ),
            }
        )
    return pd.DataFrame(out)


def training_size_figure(size: pd.DataFrame, *, ncols: int = 3) -> plt.Figure:
    """Delta with its 95% CI against n_train (log axis), one panel per family, one line per
    subset seed; 0 drawn solid."""
    families = sorted(set(size["family"])) if len(size) else []
    if not families:
        fig, ax = plt.subplots(figsize=(4, 1.5))
        ax.axis("off")
        ax.text(0.5, 0.5, "no training-size sweep in this run", ha="center", va="center")
        return fig
    nrows, ncols, figsize = panel_grid(len(families), (3.1, 2.9), max_cols=ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=figsize, squeeze=False)
    for ax in axes.flat[len(families) :]:
        ax.axis("off")
    for ax, fam in zip(axes.flat, families, strict=False):
        part = size.loc[(size["family"] == fam) & (size["status"] == "ok")]
        seeds = sorted(set(part["subset_seed"]))
        for i, s in enumerate(seeds):
            g = part.loc[part["subset_seed"] == s].sort_values("n_train")
            x = g["n_train"].to_numpy(dtype=float) * (1.0 + 0.03 * (i - (len(seeds) - 1) / 2))
            ax.errorbar(
                x,
                g["delta"],
                yerr=[g["delta"] - g["ci_low"], g["ci_high"] - g["delta"]],
                marker="o",
                ms=3,
                lw=1,
                capsize=2,
                label=f"seed {s}",
            )
        ax.axhline(0.0, color="black", lw=0.8)
        ax.set_xscale("log")
        sizes = sorted(set(part["n_train"].astype(int)))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xticks(sizes, [str(n) for n in sizes])
        null = bool(size.loc[size["family"] == fam, "null_corpus"].astype(bool).any())
        metric = part["metric"].iloc[0] if len(part) else ""
        ax.set_title(f"{fam}{' (null corpus)' if null else ''}, {metric}", fontsize=9)
        ax.set_xlabel("training rows (nested subsets)", fontsize=8)
        ax.set_ylabel("Δ = V+T − V, 95% CI", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.legend(fontsize=8)
    fig.suptitle(
        "Probe-side training-size sweep (raw V vs V+T, concat; full test split)", fontsize=10
    )
    fig.tight_layout()
    return fig
