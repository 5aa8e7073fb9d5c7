"""The force labels' bands against the true contact force (the paper validates its force bands
against measured force; the simulator knows the force of every press).

A simulated sample's force label is a band over `presses` jittered repeated presses (p05, p50,
p95 of the MuJoCo contact force) and ``force_normal`` is the contact force of its nominal,
unjittered press. `force_band_check` asks how well the band's p50 predicts that force (R^2)
and how often the band [p05, p95] holds it (coverage, with its Wilson 95 % interval), beside
the same two numbers with the true forces of other samples (a seeded derangement of the rows,
`derangement.sattolo_cycle`, the null corpus's):
the chance level a band of that width reaches on a force it was not computed from.

In simulation the bands and the true force come from one simulator, so this is a check of how
the labels are built (how much the press jitter spreads the band, whether the nominal press
lies inside it), not the paper's validation against an independent force sensor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.stats import binomtest

from tacgen_lib.corpus.derangement import sattolo_cycle

__all__ = ["FORCE_BAND_COLUMNS", "ForceBandCheck", "corpus_force_bands", "force_band_check"]

#: The corpus columns the check reads.
FORCE_BAND_COLUMNS = ("force_normal", "force_p05", "force_p50", "force_p95")


@dataclass(frozen=True)
class ForceBandCheck:
    """R^2 of p50 against the true force, coverage of [p05, p95] with its Wilson 95 % interval,
    the mean band width (N), and the same R^2 and coverage against shuffled true forces."""

    n: int
    r2: float
    coverage: float
    coverage_low: float
    coverage_high: float
    mean_width: float
    shuffled_r2: float
    shuffled_coverage: float
    shuffled_low: float
    shuffled_high: float


def _r2(y: np.ndarray, pred: np.ndarray) -> float:
    ss_res = float(np.sum((y - pred) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")


def _coverage(inside: np.ndarray) -> tuple[float, float, float]:
    k, n = int(inside.sum()), int(inside.size)
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return k / n, float(ci.low), float(ci.high)


def force_band_check(
    true_force: np.ndarray,
    p05: np.ndarray,
    p50: np.ndarray,
    p95: np.ndarray,
    *,
    seed: int,
) -> ForceBandCheck:
    """The check of the module docstring on rows with all four values finite (float64).

    Raises ValueError with fewer than 2 such rows (no R^2, no derangement) or a band whose p05
    exceeds its p95."""
    cols = [np.asarray(x, dtype=np.float64) for x in (true_force, p05, p50, p95)]
    if len({c.shape for c in cols}) != 1:
        raise ValueError("force_band_check: the four force columns differ in length")
    keep = np.all([np.isfinite(c) for c in cols], axis=0)
    f, lo, mid, hi = (c[keep] for c in cols)
    if f.size < 2:
        raise ValueError(f"force_band_check: need >= 2 rows with a true force, got {f.size}")
    bad = np.flatnonzero(lo > hi)
    if bad.size:
        raise ValueError(
            f"force_band_check: row {int(np.flatnonzero(keep)[bad[0]])} has p05 "
            f"{lo[bad[0]]:g} > p95 {hi[bad[0]]:g}"
        )
    # another sample's true force for every row: a seeded derangement (no row keeps its own)
    other = f[sattolo_cycle(f.size, np.random.default_rng(seed))]
    cov, c_lo, c_hi = _coverage((f >= lo) & (f <= hi))
    s_cov, s_lo, s_hi = _coverage((other >= lo) & (other <= hi))
    return ForceBandCheck(
        n=int(f.size),
        r2=_r2(f, mid),
        coverage=cov,
        coverage_low=c_lo,
        coverage_high=c_hi,
        mean_width=float(np.mean(hi - lo)),
        shuffled_r2=_r2(other, mid),
        shuffled_coverage=s_cov,
        shuffled_low=s_lo,
        shuffled_high=s_hi,
    )


def corpus_force_bands(frame: pd.DataFrame, *, seed: int) -> ForceBandCheck | None:
    """`force_band_check` of a corpus edge's rows, or None when there is nothing to check: a
    real corpus's edge has no force columns, fewer than 2 rows hold one, or no row has a band
    (a scene without press_jitter presses once: p05 = p50 = p95 = the nominal force, which
    would "cover" it trivially)."""
    if not set(FORCE_BAND_COLUMNS) <= set(frame.columns):
        return None
    cols = [frame[c].to_numpy(dtype=np.float64) for c in FORCE_BAND_COLUMNS]
    finite = np.all([np.isfinite(c) for c in cols], axis=0)
    if int(finite.sum()) < 2:
        return None
    if np.all(cols[1][finite] == cols[3][finite]):
        return None
    return force_band_check(*cols, seed=seed)
