"""Multiple comparisons over the probe summary: p-values, Holm and Benjamini-Hochberg.

The summary holds well over a hundred V vs V+T comparisons, each judged by its own 95% CI.
This module owns the multiplicity view of them:

- `bootstrap_p`: the one-sided p-value of H0: Delta <= 0 from the comparison's fixed-test
  bootstrap distribution (the percentile-bootstrap test that the CI inverts),
  ``p = (1 + #{Delta*_b <= 0}) / (B + 1)``; #{Delta*_b <= 0} = B (1 - p_gt0) is exact from the
  summary's ``p_gt0`` and ``n_resamples``. One-sided because the claim is V+T > V; a CI
  lower bound above 0 corresponds to p < 0.025 (`ALPHA_ONE_SIDED`).
- `holm`: Holm's step-down family-wise adjustment (float64, monotone, capped at 1).
- `benjamini_hochberg`: the BH false-discovery adjustment, equal to
  ``scipy.stats.false_discovery_control(p, method="bh")``.
- `adjust`: both, per family and over all comparisons of one protocol, as summary columns;
  `adjusted_criterion`: the paper's criterion with "CI lower bound > 0" replaced by
  "Holm-adjusted p within the comparison's family < 0.025". Per family, not over all
  comparisons: a family is one claim ("touch carries hardness"), and a bootstrap p-value
  cannot fall below 1 / (B + 1), so over m comparisons Holm can reject nothing once
  m > alpha (B + 1) (`holm_can_reject`): at B = 5,000 and alpha = 0.025 that is m > 125, and
  the default summary holds about 150. The over-all ``p_holm`` and ``p_bh`` stay as columns
  (BH, which controls the false-discovery rate, is the over-all view the report counts).
- `ci_counts`: per family and overall, how many CIs exclude 0, against the count expected by
  chance if no comparison had an effect (the null corpus's count is read against it).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

__all__ = [
    "ALPHA_ONE_SIDED",
    "adjust",
    "adjusted_criterion",
    "benjamini_hochberg",
    "bootstrap_p",
    "ci_counts",
    "holm",
    "holm_can_reject",
]

#: One-sided level matching a two-sided 95% CI's lower bound.
ALPHA_ONE_SIDED = 0.025


def bootstrap_p(p_gt0: np.ndarray, n_resamples: np.ndarray) -> np.ndarray:
    """One-sided bootstrap p-values of H0: Delta <= 0 (see the module docstring)."""
    p_gt0 = np.asarray(p_gt0, dtype=np.float64)
    b = np.asarray(n_resamples, dtype=np.float64)
    at_or_below = np.rint(b * (1.0 - p_gt0))
    return (1.0 + at_or_below) / (b + 1.0)


def _check(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, dtype=np.float64)
    if p.ndim != 1 or not (np.isfinite(p).all() and (p >= 0).all() and (p <= 1).all()):
        raise ValueError("p-values must be a 1-D array of finite values in [0, 1]")
    return p


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values: sorted ascending, p_(i) (m - i + 1), running
    maximum, capped at 1, returned in the input order."""
    p = _check(p)
    m = p.size
    if m == 0:
        return p.copy()
    order = np.argsort(p, kind="stable")
    stepped = np.maximum.accumulate((m - np.arange(m)) * p[order])
    out = np.empty(m)
    out[order] = np.minimum(stepped, 1.0)
    return out


def holm_can_reject(n_comparisons: int, n_resamples: int, alpha: float = ALPHA_ONE_SIDED) -> bool:
    """Whether Holm over `n_comparisons` bootstrap p-values of `n_resamples` resamples can
    reject anything at all: its smallest adjusted p is m / (B + 1), the smallest bootstrap p
    times m."""
    return n_comparisons / (n_resamples + 1.0) < alpha


def benjamini_hochberg(p: np.ndarray) -> np.ndarray:
    """Benjamini-Hochberg adjusted p-values (``scipy.stats.false_discovery_control``)."""
    from scipy import stats  # here: the robustness table's CI counts do not need it

    p = _check(p)
    return stats.false_discovery_control(p, method="bh") if p.size else p.copy()


def adjust(summary: pd.DataFrame) -> pd.DataFrame:
    """The main comparisons' p-values, adjusted per family and over all of one protocol.

    Adds to every row of `summary`: ``p_boot`` (`bootstrap_p`), ``p_holm`` / ``p_bh`` (over
    every ``ok`` main comparison of the row's protocol), ``p_holm_family`` / ``p_bh_family``
    (within its family and protocol) and ``criterion_adjusted`` (`adjusted_criterion`).
    Control rows and rows that did not run get NaN / null.
    """
    out = summary.copy()
    for col in ("p_boot", "p_holm", "p_bh", "p_holm_family", "p_bh_family"):
        out[col] = np.nan
    main = (out["control"] == "none") & (out["status"] == "ok")
    protocol = out["protocol"] if "protocol" in out else pd.Series("raw", index=out.index)
    out.loc[main, "p_boot"] = bootstrap_p(out.loc[main, "p_gt0"], out.loc[main, "n_resamples"])
    for _, idx in out.loc[main].groupby(protocol[main]).groups.items():
        out.loc[idx, "p_holm"] = holm(out.loc[idx, "p_boot"].to_numpy())
        out.loc[idx, "p_bh"] = benjamini_hochberg(out.loc[idx, "p_boot"].to_numpy())
    for _, idx in out.loc[main].groupby([protocol[main], out.loc[main, "family"]]).groups.items():
        out.loc[idx, "p_holm_family"] = holm(out.loc[idx, "p_boot"].to_numpy())
        out.loc[idx, "p_bh_family"] = benjamini_hochberg(out.loc[idx, "p_boot"].to_numpy())
    out["criterion_adjusted"] = pd.array(
        [
            adjusted_criterion(r.delta, r.p_holm_family, r.delta_ctrl, r.criterion_met)
            for r in out[["delta", "p_holm_family", "delta_ctrl", "criterion_met"]].itertuples()
        ],
        dtype="boolean",
    )
    return out


def adjusted_criterion(
    delta: float, p_holm: float, delta_ctrl: float, criterion: object, min_delta: float = 0.03
) -> bool | None:
    """The paper's criterion with its CI test made family-wise: Delta >= min_delta, Holm p
    (within the comparison's family and protocol, see the module docstring) <
    `ALPHA_ONE_SIDED`, Delta_ctrl < Delta. Null where the paper's criterion is null (no
    control ran)."""
    if (
        criterion is None
        or criterion is pd.NA
        or (isinstance(criterion, float) and math.isnan(criterion))
    ):
        return None
    if not all(np.isfinite([delta, p_holm, delta_ctrl])):
        return None
    return bool(delta >= min_delta and p_holm < ALPHA_ONE_SIDED and delta_ctrl < delta)


def ci_counts(summary: pd.DataFrame, *, level: float = 0.95) -> pd.DataFrame:
    """Per family (and ``all``) of each protocol: comparisons, CIs excluding 0 (above, below),
    the count expected by chance with no effect anywhere ((1 - level) x m, both sides), the
    Holm / BH rejections at `ALPHA_ONE_SIDED` and whether the family is a null corpus.

    Expects `adjust`'s columns. The chance count assumes independent comparisons; the
    comparisons of a family share test rows and the V probe, so the count varies more.
    """
    main = summary.loc[(summary["control"] == "none") & (summary["status"] == "ok")].copy()
    if "protocol" not in main:
        main["protocol"] = "raw"
    rows = []
    for protocol, part in main.groupby("protocol", sort=True):
        null = part["null_corpus"].astype(bool)
        groups = [*part.groupby("family", sort=True), ("all", part)]
        if null.any():
            groups.append(("null corpora", part.loc[null]))
        for fam, g in groups:
            m = len(g)
            above = int((g["ci_low"] > 0).sum())
            below = int((g["ci_high"] < 0).sum())
            pooled = fam in ("all", "null corpora")
            suffix = "" if pooled else "_family"
            rows.append(
                {
                    "protocol": protocol,
                    "family": fam,
                    "null_corpus": bool(g["null_corpus"].astype(bool).all()),
                    "comparisons": m,
                    "ci_excludes_0": above + below,
                    "ci_above_0": above,
                    "ci_below_0": below,
                    "expected_by_chance": (1.0 - level) * m,
                    "holm_rejections": int((g[f"p_holm{suffix}"] < ALPHA_ONE_SIDED).sum()),
                    "bh_rejections": int((g[f"p_bh{suffix}"] < ALPHA_ONE_SIDED).sum()),
                    "criterion_met": int(g["criterion_met"].fillna(False).astype(bool).sum()),
                    "criterion_adjusted": int(
                        g["criterion_adjusted"].fillna(False).astype(bool).sum()
                    ),
                }
            )
    return pd.DataFrame(rows)
