"""How every number of the report is written: one place, so no page writes one differently.

- scores and other reals to 3 decimals (`number`), deltas signed (`signed`), a value with its
  interval as ``x [lo, hi]`` (`with_ci`);
- a value that is not defined is a dash (`MISSING`), never ``nan``; the table that shows it says
  why in a footnote (`tables.to_html`'s ``missing``);
- rounding never writes ``-0.000``: a value that rounds to zero is ``0.000`` (``+0.000`` signed);
- integers as integers, also when a column holds them as floats (a count column that passed
  through a join with missing rows);
- `numeric_order`: class labels sorted by value, not as text (500, 2000, 5000, not 2000, 500,
  5000).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable

import numpy as np
import pandas as pd

__all__ = [
    "MISSING",
    "DECIMALS",
    "is_missing",
    "number",
    "signed",
    "with_ci",
    "cell",
    "column_cells",
    "numeric_order",
]

MISSING = "—"
DECIMALS = 3


def is_missing(x: object) -> bool:
    """None, pandas NA/NaT, or a float NaN."""
    if x is None or x is pd.NA or x is pd.NaT:
        return True
    return isinstance(x, numbers.Real) and not isinstance(x, numbers.Integral) and math.isnan(x)


def _fixed(x: float, decimals: int, sign: bool) -> str:
    text = f"{x:+.{decimals}f}" if sign else f"{x:.{decimals}f}"
    digits = text.lstrip("+-")
    if set(digits) <= {"0", "."}:  # rounds to zero: no "-0.000"
        return ("+" if sign else "") + digits
    return text


def number(x: object, decimals: int = DECIMALS) -> str:
    """A real to `decimals` decimals, an integer as itself; `MISSING` for a missing value;
    ±inf as ``∞``/``−∞``."""
    if is_missing(x):
        return MISSING
    if isinstance(x, numbers.Integral):
        return str(int(x))
    v = float(x)  # type: ignore[arg-type]
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    return _fixed(v, decimals, sign=False)


def signed(x: object, decimals: int = DECIMALS) -> str:
    """A difference, always with its sign (``+0.012``, ``-0.030``, ``+0.000``)."""
    if is_missing(x):
        return MISSING
    v = float(x)  # type: ignore[arg-type]
    if math.isinf(v):
        return "+∞" if v > 0 else "−∞"
    return _fixed(v, decimals, sign=True)


def with_ci(
    x: object, lo: object, hi: object, *, sign: bool = False, decimals: int = DECIMALS
) -> str:
    """``x [lo, hi]``; ``x`` alone with the reason when the interval is missing (one point:
    there is nothing to resample)."""
    f = signed if sign else number
    if is_missing(x):
        return MISSING
    if is_missing(lo) or is_missing(hi):
        return f"{f(x, decimals)} (no interval: one point)"
    return f"{f(x, decimals)} [{f(lo, decimals)}, {f(hi, decimals)}]"


def _integral_column(values: pd.Series) -> bool:
    """A float column holding counts: every defined value integral, and not all in [-1, 1]
    (a score column of zeros and ones stays a score)."""
    v = pd.to_numeric(values, errors="coerce").dropna().to_numpy(dtype=float)
    return v.size > 0 and bool(np.all(v == np.round(v))) and bool(np.any(np.abs(v) > 1))


def cell(x: object, *, integral: bool = False, sign: bool = False) -> str:
    """One table cell: numbers as above, booleans as yes/no, anything else as its text."""
    if isinstance(x, bool | np.bool_):
        return "yes" if x else "no"
    if is_missing(x):
        return MISSING
    if isinstance(x, numbers.Real):
        if integral or isinstance(x, numbers.Integral):
            return str(int(x)) if not (sign and x > 0) else f"+{int(x)}"
        return signed(x) if sign else number(x)
    return str(x)


def column_cells(values: pd.Series, *, sign: bool = False) -> list[str]:
    """Every cell of a column, with the column's integer test applied once."""
    integral = values.dtype.kind == "f" and _integral_column(values)
    return [cell(x, integral=integral, sign=sign) for x in values]


def numeric_order(labels: Iterable[object]) -> list[object]:
    """Labels in numeric order where every label reads as a number, else in text order."""
    labels = list(labels)
    try:
        return sorted(labels, key=lambda s: float(s))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return sorted(labels, key=str)
