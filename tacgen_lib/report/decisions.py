"""The decisions the findings page states, one row each: what is compared, its value and
interval, the threshold it is read against, and the decision taken.

A verdict sentence on the findings page (`tacgen_lib.report.findings`) is written from
decisions (`tacgen_lib.report.claims`); the same decisions are written as an edge (rule
findings, `tacgen_lib.io.run_compare.DECISIONS`), so two runs of one config on other machines,
kernels or devices can be compared by their conclusions, not their bytes
(`tacgen_lib.io.run_compare.compare_decisions`, `tools/device_check.py --compare`).

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

__all__ = [
    "DECISION_COLUMNS",
    "SIDE_DECISIONS",
    "FindingsPart",
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
