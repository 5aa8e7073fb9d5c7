"""The decisions the findings page states, one row each: what is compared, its value and
interval, the threshold it is read against, and the decision taken.

A verdict sentence on the findings page (`tacgen_lib.report.findings`) is written from
decisions (`tacgen_lib.report.claims`); the same decisions are written as an edge (rule
findings, ``results/report/findings/decisions.parquet``), so two runs of one config on other
machines, kernels or devices can be compared by their conclusions, not their bytes
(`compare_decisions`, `tools/compare_runs.py`).

A decision is a short word from a fixed vocabulary per kind of claim (`SIDE_DECISIONS` for a
difference read against 0, ``passes`` / ``fails`` for a gate, ...), never a sentence, so that
two runs agree exactly when they state the same conclusion.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import NamedTuple

import pandas as pd

from tacgen_lib.report import claims
from tacgen_lib.report_pages import DECISIONS_EDGE

__all__ = [
    "DECISION_COLUMNS",
    "DECISION_COMPARISON_COLUMNS",
    "DECISIONS_EDGE",
    "SIDE_DECISIONS",
    "FindingsPart",
    "compare_decisions",
    "decision",
    "decisions_frame",
    "side_decision",
]

#: The columns of the decisions edge, keyed by ``decision_id``.
DECISION_COLUMNS = [
    "decision_id",  # stable across runs of one config: evidence|what is compared
    "evidence",  # the findings row's branch (probe, generation, regime, ...)
    "what",  # what is compared, in words
    "value",  # the number decided on (NaN where the decision reads none)
    "ci_low",  # its interval (NaN without one)
    "ci_high",
    "threshold",  # what the value or interval is read against (NaN where none)
    "decision",  # the decision, a short word of its kind's vocabulary
]

#: A difference read against 0 by its 95 % interval (`claims.interval_side`) -> the decision.
SIDE_DECISIONS = {
    "above": "above 0",
    "below": "below 0",
    "touches": "no measurable difference",
    "spans": "no measurable difference",
    "none": "no interval",
}

#: The columns of `compare_decisions`.
DECISION_COMPARISON_COLUMNS = [
    "decision_id",
    "status",  # same | differs | only in a | only in b
    "decision_a",
    "decision_b",
    "value_a",
    "value_b",
    "ci_a",
    "ci_b",
    "threshold",
]


class FindingsPart(NamedTuple):
    """One evidence branch's findings rows (`tacgen_lib.report_pages.FINDINGS_COLUMNS`) and the
    decisions their verdicts state (rows of `DECISION_COLUMNS`)."""

    rows: pd.DataFrame
    decisions: list[dict]


def side_decision(lo: float, hi: float) -> str:
    """The decision on a difference with its 95 % interval: `SIDE_DECISIONS` of
    `claims.interval_side`."""
    return SIDE_DECISIONS[claims.interval_side(lo, hi)]


def _num(x: object) -> float:
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan
    return v


def decision(
    decision_id: str,
    evidence: str,
    what: str,
    decided: str,
    *,
    value: float = math.nan,
    ci_low: float = math.nan,
    ci_high: float = math.nan,
    threshold: float = math.nan,
) -> dict:
    """One row of `DECISION_COLUMNS`."""
    return {
        "decision_id": decision_id,
        "evidence": evidence,
        "what": what,
        "value": _num(value),
        "ci_low": _num(ci_low),
        "ci_high": _num(ci_high),
        "threshold": _num(threshold),
        "decision": str(decided),
    }


def decisions_frame(rows: Iterable[Mapping]) -> pd.DataFrame:
    """The decisions as a frame of `DECISION_COLUMNS`; a decision id stated twice is an
    error naming it (two findings rows would then decide one thing twice)."""
    frame = pd.DataFrame(list(rows), columns=DECISION_COLUMNS)
    dup = frame["decision_id"][frame["decision_id"].duplicated()]
    if len(dup):
        raise ValueError(f"decisions: decision_id {dup.iloc[0]!r} is stated twice")
    for col in ("value", "ci_low", "ci_high", "threshold"):
        frame[col] = frame[col].astype("float64")
    return frame


def _ci(r: Mapping, suffix: str) -> str:
    lo, hi = r.get(f"ci_low{suffix}"), r.get(f"ci_high{suffix}")
    if lo is None or hi is None or (pd.isna(lo) and pd.isna(hi)):
        return ""
    return f"[{lo:.4g}, {hi:.4g}]"


def compare_decisions(a: pd.DataFrame, b: pd.DataFrame) -> pd.DataFrame:
    """Two runs' decisions joined on ``decision_id`` (`DECISION_COMPARISON_COLUMNS`): ``same``
    where both state the same decision, ``differs`` where not, ``only in a`` / ``only in b``
    where one run states a decision the other does not. Values and intervals are shown beside,
    not compared: two machines may round a value differently and still decide alike."""
    m = a.merge(b, on="decision_id", how="outer", suffixes=("_a", "_b"), indicator=True)
    rows = []
    for r in m.to_dict("records"):
        if r["_merge"] == "left_only":
            status = "only in a"
        elif r["_merge"] == "right_only":
            status = "only in b"
        else:
            status = "same" if r["decision_a"] == r["decision_b"] else "differs"
        threshold = r.get("threshold_a")
        if threshold is None or pd.isna(threshold):
            threshold = r.get("threshold_b")
        rows.append(
            {
                "decision_id": r["decision_id"],
                "status": status,
                "decision_a": r.get("decision_a"),
                "decision_b": r.get("decision_b"),
                "value_a": r.get("value_a"),
                "value_b": r.get("value_b"),
                "ci_a": _ci(r, "_a"),
                "ci_b": _ci(r, "_b"),
                "threshold": threshold,
            }
        )
    out = pd.DataFrame(rows, columns=DECISION_COMPARISON_COLUMNS)
    return out.sort_values("decision_id", ignore_index=True)
