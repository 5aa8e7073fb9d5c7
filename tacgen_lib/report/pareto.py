"""Reading a knob's points: the Pareto front, one sentence per knob, the marginal gain per minute.

Input is the points table of `tacgen_lib.cost.points` (one row per knob x setting x metric,
`direction` "higher" | "lower"). Everything here is a pure function of those numbers:

- `pareto_front`: the settings no other setting beats on both seconds (fewer) and metric
  (better in the metric's direction);
- `knob_sentence`: what moving the knob away from its default buys and costs, in words
  written from the numbers (how far the metric moves, and how many times as long the job
  takes);
- `marginal_table`: between consecutive points of each front, the metric gained per extra
  minute of wall time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from tacgen_lib.cost.points import DIRECTIONS
from tacgen_lib.report import format as fmt
from tacgen_lib.report.claims import gain_within_uncertainty

__all__ = ["MARGINAL_COLUMNS", "improvement", "knob_sentence", "marginal_table", "pareto_front"]

MARGINAL_COLUMNS = [
    "knob",
    "metric",
    "from",
    "to",
    "extra_s",
    "gain",
    "gain_per_min",
    "within_uncertainty",
]


def _sign(direction: str) -> float:
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    return 1.0 if direction == "higher" else -1.0


def improvement(a: float, b: float, direction: str) -> float:
    """How much better `b` is than `a` in the metric's direction (negative: worse)."""
    return _sign(direction) * (b - a)


def pareto_front(seconds: Sequence[float], values: Sequence[float], direction: str) -> np.ndarray:
    """Boolean mask of the points on the Pareto front (fewer seconds, better metric).

    A point is dominated when another point costs no more seconds and scores no worse, and
    is strictly better on one of the two. Ties (same seconds and value) all stay on the front.
    Points with a non-finite value or time are never on it.
    """
    s = np.asarray(seconds, dtype=np.float64)
    v = _sign(direction) * np.asarray(values, dtype=np.float64)
    if s.shape != v.shape or s.ndim != 1:
        raise ValueError(f"pareto_front: seconds {s.shape} and values {v.shape} must be 1-D alike")
    ok = np.isfinite(s) & np.isfinite(v)
    front = ok.copy()
    for i in np.flatnonzero(ok):
        others = ok & (s <= s[i]) & (v >= v[i]) & ((s < s[i]) | (v > v[i]))
        front[i] = not others.any()
    return front


def _num(x: float) -> str:
    """Seconds as the page prints them: 3 significant digits, thousands separated (metric
    values go through `tacgen_lib.report.format`, like every other number of the report)."""
    if not math.isfinite(x):
        return "n/a"
    if x == 0:
        return "0"
    if abs(x) >= 100:
        return f"{x:,.0f}"
    return f"{x:.3g}"


def _ratio(a: float, b: float) -> str:
    return f"{b / a:.1f}×" if a > 0 else "n/a"


def knob_sentence(points: pd.DataFrame, unit: str = "") -> str:
    """One sentence on a knob's metric from its points (one knob, one metric, >= 1 setting).

    "What does more X buy, and for how long": compares the default setting with the next
    larger setting of the knob (the next smaller if the default is the largest; the smallest
    with the largest if no setting is the default): the metric's change, whether the cheaper
    setting's value lies inside the dearer one's interval (`claims.gain_within_uncertainty`:
    not measurable; the marginal table uses the same test) and the ratio of wall times. Then
    names the cheapest setting whose value lies inside the default's interval (what could be
    saved without a measurable loss), and whether the default is on the Pareto front.
    Settings are ordered by `setting` (then by seconds); `unit` follows their labels.
    """
    if points.empty:
        raise ValueError("knob_sentence: no points")
    if points["knob"].nunique() != 1 or points["metric"].nunique() != 1:
        raise ValueError("knob_sentence: pass the points of one knob and one metric")
    p = points.sort_values(["setting", "wall_s"], kind="stable").reset_index(drop=True)
    direction = str(p["direction"].iloc[0]) if "direction" in p.columns else "higher"
    knob, metric = str(p["knob"].iloc[0]), str(p["metric"].iloc[0])

    def lab(r: pd.Series) -> str:
        return f"{r['label']} {unit}".strip()

    if len(p) == 1:
        r = p.iloc[0]
        return f"{knob}: one setting ({lab(r)}), {metric} {fmt.number(r['value'])} in {_num(r['wall_s'])} s."
    defaults = np.flatnonzero(p["is_default"].astype(bool).to_numpy())
    if defaults.size:
        i = int(defaults[0])
        j = i + 1 if i + 1 < len(p) else i - 1
    else:
        i, j = 0, len(p) - 1
    d, other = p.iloc[i], p.iloc[j]
    gain = improvement(d["value"], other["value"], direction)
    has_ci = math.isfinite(d["ci_low"]) and math.isfinite(d["ci_high"])
    verb = "improves" if gain > 0 else "worsens" if gain < 0 else "does not change"
    change = f"{metric} {verb}" + (f" by {fmt.number(abs(gain))}" if gain != 0 else "")
    change += f" ({fmt.number(d['value'])} → {fmt.number(other['value'])}"
    cheap, dear = (d, other) if d["wall_s"] <= other["wall_s"] else (other, d)
    if math.isfinite(dear["ci_low"]) and math.isfinite(dear["ci_high"]):
        inside = gain_within_uncertainty(cheap["value"], dear["ci_low"], dear["ci_high"])
        change += f", {'inside' if inside else 'outside'} the interval of {lab(dear)})"
    else:
        change += ")"
    start = "from the default " if defaults.size else "from "
    text = (
        f"{knob}: {start}{lab(d)} to {lab(other)}, {change} and the job takes "
        f"{_ratio(d['wall_s'], other['wall_s'])} as long ({_num(d['wall_s'])} s → "
        f"{_num(other['wall_s'])} s)."
    )
    if defaults.size and has_ci:
        inside = [gain_within_uncertainty(v, d["ci_low"], d["ci_high"]) for v in p["value"]]
        cheap = p[np.asarray(inside, dtype=bool) & (p["wall_s"] < d["wall_s"]).to_numpy()]
        cheap = cheap.sort_values("wall_s", kind="stable")
        if len(cheap):
            c = cheap.iloc[0]
            text += (
                f" {lab(c)} is within the default's uncertainty at "
                f"{_ratio(d['wall_s'], c['wall_s'])} its time."
            )
    if defaults.size:
        on = pareto_front(p["wall_s"], p["value"], direction)[i]
        text += " The default is on the Pareto front." if on else " The default is dominated."
    return text


def marginal_table(points: pd.DataFrame) -> pd.DataFrame:
    """Between consecutive Pareto points of every knob and metric (in order of seconds): the
    extra wall seconds, the metric gained (in its improving direction), the gain per extra
    minute, and whether the cheaper value lies inside the dearer point's interval (the gain is
    not measurable: `claims.gain_within_uncertainty`, the test the knob sentences use)."""
    out = []
    for (knob, metric), g in points.groupby(["knob", "metric"], sort=False):
        direction = str(g["direction"].iloc[0]) if "direction" in g.columns else "higher"
        front = g[pareto_front(g["wall_s"], g["value"], direction)]
        front = front.sort_values("wall_s", kind="stable")
        rows = list(front.itertuples(index=False))
        for a, b in zip(rows, rows[1:], strict=False):
            extra = float(b.wall_s - a.wall_s)
            gain = improvement(float(a.value), float(b.value), direction)
            # the same test as the knob sentences': the cheaper value inside the dearer
            # point's interval (the gain is not measurable at its precision)
            within = gain_within_uncertainty(float(a.value), float(b.ci_low), float(b.ci_high))
            out.append(
                (
                    knob,
                    metric,
                    str(a.label),
                    str(b.label),
                    extra,
                    gain,
                    gain / (extra / 60.0) if extra > 0 else math.nan,
                    within,
                )
            )
    return pd.DataFrame(out, columns=MARGINAL_COLUMNS)
