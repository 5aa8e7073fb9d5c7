"""The report page *Backbone families* (`tacgen_lib.probes.backbone_families`): V, V+T and
Delta with its fixed-test CI per backbone family, probe family and protocol (linear beside the
2-layer probe), the null corpus's rows beside the real ones as the control, and one sentence
per family saying whether the V+T direction holds there, from the numbers."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from tacgen_lib.report import claims
from tacgen_lib.report import format as fmt

__all__ = ["PROTOCOL_LABELS", "direction_holds", "family_sentences", "family_table", "null_gains"]

PROTOCOL_LABELS = {"raw": "linear", "standardised": "linear, standardised", "mlp2": "2-layer MLP"}


def _ordered(rows: pd.DataFrame, order: Sequence[str]) -> pd.DataFrame:
    rank = {f: i for i, f in enumerate(order)}
    prot = {p: i for i, p in enumerate(PROTOCOL_LABELS)}
    return rows.assign(_f=rows["family"].map(rank), _p=rows["protocol"].map(prot)).sort_values(
        ["_f", "null_corpus", "probe", "_p"], ignore_index=True
    )


def family_table(rows: pd.DataFrame, order: Sequence[str]) -> pd.DataFrame:
    """One row per family x probe family x protocol, in the configured family order, the null
    corpus's probes after the real ones."""
    r = _ordered(rows, order)
    return pd.DataFrame(
        {
            "family": r["family"],
            "V backbone": r["vision_backbone"],
            "T backbone": r["tactile_backbone"],
            "probe": [
                f"{x.probe} ({x.corpus}{', null' if x.null_corpus else ''})" for x in r.itertuples()
            ],
            "probe kind": r["protocol"].map(PROTOCOL_LABELS).fillna(r["protocol"]),
            "metric": r["metric"],
            "V": [fmt.number(x) for x in r["v_score"]],
            "V+T": [fmt.number(x) for x in r["vt_score"]],
            "Δ [95% CI]": [
                "failed: " + x.notes
                if x.status != "ok"
                else fmt.with_ci(x.delta, x.ci_low, x.ci_high, sign=True)
                for x in r.itertuples()
            ],
            "n train/test": [f"{x.n_train}/{x.n_test}" for x in r.itertuples()],
        }
    )


def direction_holds(g: pd.DataFrame) -> bool:
    """Whether the V+T direction holds for one family's rows: every real-corpus Δ under the
    linear probe is positive (a probe that failed is not)."""
    linear = g[(g["protocol"] == "raw") & ~g["null_corpus"]]
    return len(linear) > 0 and bool((linear["delta"] > 0).all())


def null_gains(g: pd.DataFrame) -> pd.DataFrame:
    """The null-corpus rows whose CI lies above 0: touch carries no label there, so each is a
    defect to report (UNEXPECTED)."""
    return g[g["null_corpus"] & (g["ci_low"] > 0)]


def _count(g: pd.DataFrame, side: str) -> str:
    ok = g[g["status"] == "ok"]
    n = sum(claims.interval_side(x.ci_low, x.ci_high) == side for x in ok.itertuples())
    return f"{n} of {len(g)}"


def _weaker_mlp_v(g: pd.DataFrame) -> list[str]:
    """Probe families where the 2-layer V scores below the linear V by more than 0.05 (a
    weak baseline inflates the 2-layer Δ)."""
    ok = g[g["status"] == "ok"].set_index(["probe", "protocol"])["v_score"]
    return [
        probe
        for probe in dict.fromkeys(g["probe"])
        if (probe, "mlp2") in ok
        and (probe, "raw") in ok
        and ok[(probe, "mlp2")] < ok[(probe, "raw")] - 0.05
    ]


def family_sentences(rows: pd.DataFrame, order: Sequence[str]) -> list[str]:
    """Per family: under each protocol, on how many real-corpus probes V+T beats V (point and
    CI above 0), and on how many null-corpus probes a CI lies above 0 (where touch carries
    no label, so any would be a defect). "The direction holds" when every real-corpus Δ is
    positive under the linear probe. A 2-layer V well below the linear V is named: it makes
    the 2-layer Δ look larger than what touch adds."""
    out = []
    r = _ordered(rows, order)
    for family in dict.fromkeys(r["family"]):
        g = r[r["family"] == family]
        first = g.iloc[0]
        parts = []
        for protocol, p in g.groupby("protocol", sort=False):
            real, null = p[~p["null_corpus"]], p[p["null_corpus"]]
            positive = int((real["delta"] > 0).sum())
            text = (
                f"{PROTOCOL_LABELS.get(protocol, protocol)}: Δ > 0 on {positive} of {len(real)} "
                f"real-corpus probes, CI above 0 on {_count(real, 'above')}"
            )
            if len(null):
                text += f"; null corpus CI above 0 on {_count(null, 'above')}"
            parts.append(text)
        unexpected = null_gains(g)
        verdict = (
            "The V+T direction holds"
            if direction_holds(g)
            else "The V+T direction does not hold on every real-corpus probe"
        )
        if len(unexpected):
            verdict += (
                "; UNEXPECTED: V+T beats V on the null corpus, where touch carries no label "
                "("
                + ", ".join(
                    f"{x.probe}, {PROTOCOL_LABELS.get(x.protocol, x.protocol)}"
                    for x in unexpected.itertuples()
                )
                + ")"
            )
        sentence = (
            f"{family} (V {first['vision_backbone']}, T {first['tactile_backbone']}): "
            f"{verdict}. " + "; ".join(parts) + "."
        )
        weak = _weaker_mlp_v(g)
        if weak:
            sentence += (
                f" The 2-layer probe's V scores below the linear V on {', '.join(weak)}: its Δ "
                "there is measured against a weaker V, so the linear row is the fairer one."
            )
        out.append(sentence)
    return out
