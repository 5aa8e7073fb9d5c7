"""The regime's arms (`tacgen_lib.generate.regime` fits them): the (arm, probe) pairs of a cell
(`ARMS`), the summary's columns, the probe settings and rows of a target, the designs of the
pool-aware baseline (generalised distillation) and of the vision ceiling, and one summary row
per arm of a fitted cell (`cell_rows`: scores, CIs and Deltas on shared fixed-test resamples).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from tacgen_lib.generate.ladder import LADDER
from tacgen_lib.generate.regime_sets import RegimeSets, RegimeSettings
from tacgen_lib.generate.small_probes import SmallFit, fit_small_probe
from tacgen_lib.probes.bootstrap import percentile_interval, score_resamples
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.rows import FamilyRows, visible_design
from tacgen_lib.probes.settings import ProbeSettings

__all__ = [
    "ARMS",
    "SUMMARY_COLUMNS",
    "RegimeTarget",
    "appearance_design",
    "cell_rows",
    "distillation_rows",
    "gap_closed",
    "headroom_captured",
    "regime_probe_settings",
    "regime_test_rows",
]

#: (arm, probe) pairs of a regime cell, in report order.
ARMS: tuple[tuple[str, str], ...] = (
    ("v", "linear"),
    ("v", "nonlinear"),
    *((rung, probe) for rung in LADDER for probe in ("linear", "nonlinear")),
    ("v_tgen_shuffled", "linear"),
    ("distilled", "linear"),
    ("distilled", "nonlinear"),
    ("v_treal", "linear"),
    ("v_ceiling", "linear"),
    ("v_ceiling", "nonlinear"),
    ("vision_ceiling", "oracle"),
)

#: Columns of ``results/generate/regime/summary.parquet`` (one row per cell x target x arm).
SUMMARY_COLUMNS = (
    "row_id",
    "corpus",
    "rho",
    "n_labelled",
    "n_pool",
    "seed",
    "draw",
    "target",
    "kind",
    "metric",
    "arm",
    "probe",
    "score",
    "ci_low",
    "ci_high",
    "delta_vs_linear_v",
    "ci_low_vs_linear_v",
    "ci_high_vs_linear_v",
    "delta_vs_nonlinear_v",
    "ci_low_vs_nonlinear_v",
    "ci_high_vs_nonlinear_v",
    "gap_closed",
    "headroom_captured",
    "delta_vs_distilled",
    "ci_low_vs_distilled",
    "ci_high_vs_distilled",
    "majority",
    "below_majority",
    "reg",
    "reg_source",
    "n_test",
    "n_labelled_classes",
)


def regime_probe_settings(settings: ProbeSettings, regime: RegimeSettings) -> ProbeSettings:
    """The probes stage's settings of a target with the regime's grids (`RegimeSettings.C`,
    ``lambdas``): penalties strong enough for a probe on a few rows to fall back to the
    majority class (or the mean) instead of overfitting."""
    return replace(
        settings,
        C=tuple(float(c) for c in regime.C),
        lambdas=tuple(float(v) for v in regime.lambdas),
    )


def regime_test_rows(rows: FamilyRows, sets: RegimeSets) -> FamilyRows:
    """`rows` (a target's `family_rows`) with its test rows checked to be the sets' test rows."""
    if set(map(str, rows.test_ids)) != set(map(str, sets.test)):
        raise ValueError(
            f"regime: target {rows.target!r} of corpus {rows.corpus!r} has test rows other than "
            "the split's (a test row without a label?)"
        )
    return rows


def distillation_rows(
    v_lab: np.ndarray,
    t_lab: np.ndarray,
    y_lab: np.ndarray,
    v_pool: np.ndarray,
    t_pool: np.ndarray,
    settings: ProbeSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """The student's training rows of generalised distillation (Lopez-Paz et al. 2016), with
    hard labels: the labelled rows' V with their true labels, then the pool rows' V with the
    labels of a teacher, the probe on [V, real T] fitted on the labelled rows, predicted
    through the pool's real touch. Returns (x, y)."""
    teacher = fit_small_probe(
        np.hstack([v_lab, t_lab]), y_lab, np.hstack([v_pool, t_pool]), settings
    )
    if settings.kind == "ridge":
        y_all = np.concatenate([np.asarray(y_lab, np.float64), teacher.pred.astype(np.float64)])
    else:
        y_all = np.concatenate([np.asarray(y_lab, dtype=object), teacher.pred.astype(object)])
    return np.vstack([v_lab, v_pool]), y_all


def appearance_design(
    train: pd.DataFrame, test: pd.DataFrame, *, log_target: bool, n_classes: int
) -> tuple[np.ndarray, np.ndarray]:
    """The vision ceiling's design: one-hot of the true appearance class (``appearance_id``,
    0..n_classes-1) beside the visible shape and size (`visible_design`); for mass targets
    the class one-hot times the size term too (mass = density x volume: E[mass | appearance,
    size] is E[density | appearance] x volume)."""
    vis_tr, vis_te = visible_design(train, test, log_target=log_target)

    def onehot(frame: pd.DataFrame) -> np.ndarray:
        ids = frame["appearance_id"].to_numpy(dtype=np.int64)
        return (ids[:, None] == np.arange(n_classes)[None, :]).astype(np.float64)

    oh_tr, oh_te = onehot(train), onehot(test)
    size_tr = train["scale"].to_numpy(np.float64) ** 3
    size_te = test["scale"].to_numpy(np.float64) ** 3
    if log_target:
        return np.hstack([oh_tr, vis_tr]), np.hstack([oh_te, vis_te])
    scale = size_tr.std() or 1.0
    return (
        np.hstack([oh_tr, vis_tr, oh_tr * (size_tr / scale)[:, None]]),
        np.hstack([oh_te, vis_te, oh_te * (size_te / scale)[:, None]]),
    )


def gap_closed(arm: float, nonlinear_v: float, real: float) -> float:
    """(arm - nonlinear V) / (real - nonlinear V): 0 = no better than nonlinear V, 1 = as good
    as real touch; NaN when real touch is no better than nonlinear V (nothing to close)."""
    gap = real - nonlinear_v
    if not np.isfinite(gap) or gap <= 0:
        return math.nan
    return (arm - nonlinear_v) / gap


def headroom_captured(arm: float, nonlinear_v: float, ceiling: float, headroom_low: float) -> float:
    """(arm - nonlinear V) / (V ceiling - nonlinear V), the share of the headroom above
    nonlinear V (up to the nonlinear V ceiling) that an arm captures, only where that headroom
    exceeds its own noise: `headroom_low`, the lower bound of the paired fixed-test bootstrap
    CI of V ceiling - nonlinear V (the ceiling row's ``ci_low_vs_nonlinear_v``), lies above 0.
    NaN otherwise: a ratio over a headroom the test rows cannot tell from 0 reads as anything
    (a headroom near 0 makes an arm as far above nonlinear V capture all of it)."""
    if not (np.isfinite(headroom_low) and headroom_low > 0):
        return math.nan
    return gap_closed(arm, nonlinear_v, ceiling)


@dataclass(frozen=True)
class RegimeTarget:
    """One target of the regime: its rows (train = every non-test row, test = the test
    split), its probe settings (`regime_probe_settings`) and the manifest rows of the
    vision ceiling."""

    rows: FamilyRows
    settings: ProbeSettings
    manifest: pd.DataFrame  # sample_id-indexed: appearance_id, shape, scale


def cell_rows(
    fits: Mapping[tuple[str, str], SmallFit],
    y_test: np.ndarray,
    idx: np.ndarray,
    metric: str,
    *,
    base: dict,
) -> list[dict]:
    """One summary row per arm of a cell (`ARMS` order) that `fits` holds: score with CI,
    Deltas vs linear and nonlinear V and vs generalised distillation with the same probe
    (linear for the other arms). V (linear and nonlinear) and V + real T must be fitted; a
    cell without generalised distillation or the V ceiling (the positive control's,
    `generate.look_control`) gets NaN for the Deltas against it and for the headroom.

    Every arm is scored on every fixed-test resample of `idx` at once (`score_resamples`:
    one count matrix for the cell); a CI is the percentile interval of an arm's resampled
    scores, a Delta's the interval of the paired differences, as `fixed_test_bootstrap`
    computes them for one pair of probes.
    """
    if metric == "r2":
        y_test = y_test.astype(np.float64)
    keys = list(fits)
    for k in keys:
        pred = np.asarray(fits[k].pred)
        if pred.shape != y_test.shape or (
            metric == "r2" and not np.isfinite(pred.astype(np.float64)).all()
        ):
            raise ValueError(
                f"regime cell {base['corpus']} N_L={base['n_labelled']} {base['target']}: "
                f"arm {'/'.join(k)} predicted {pred.shape} values, not {y_test.shape} finite ones"
            )
    resampled, _ = score_resamples(metric, y_test, [fits[k].pred for k in keys], idx)
    on_resamples = dict(zip(keys, resampled, strict=True))
    full = {k: score(metric, y_test, fits[k].pred) for k in keys}

    def versus(ref: tuple[str, str], k: tuple[str, str]) -> tuple[float, float, float]:
        if ref not in full or k not in full:  # an arm the cell did not fit (the control's)
            return math.nan, math.nan, math.nan
        lo, hi = percentile_interval(on_resamples[k] - on_resamples[ref])
        return full[k] - full[ref], lo, hi

    real, nl = full[("v_treal", "linear")], full[("v", "nonlinear")]
    ceiling = full.get(("v_ceiling", "nonlinear"), math.nan)
    # the headroom's own noise: its paired CI (V ceiling - nonlinear V) must lie above 0
    _, headroom_low, _ = versus(("v", "nonlinear"), ("v_ceiling", "nonlinear"))
    key = (
        f"{base['corpus']}|{base['n_labelled']}|{base['n_pool']}|{base['seed']}|"
        f"d{base['draw']}|{base['target']}"
    )
    rows = []
    for arm, probe in (k for k in ARMS if k in fits):
        k = (arm, probe)
        lo, hi = percentile_interval(on_resamples[k])
        d_lin, lo_lin, hi_lin = versus(("v", "linear"), k)
        d_nl, lo_nl, hi_nl = versus(("v", "nonlinear"), k)
        d_gd, lo_gd, hi_gd = versus(
            ("distilled", "nonlinear" if probe == "nonlinear" else "linear"), k
        )
        rows.append(
            {
                "row_id": f"{key}|{arm}|{probe}",
                **base,
                "arm": arm,
                "probe": probe,
                "score": full[k],
                "ci_low": lo,
                "ci_high": hi,
                "delta_vs_linear_v": d_lin,
                "ci_low_vs_linear_v": lo_lin,
                "ci_high_vs_linear_v": hi_lin,
                "delta_vs_nonlinear_v": d_nl,
                "ci_low_vs_nonlinear_v": lo_nl,
                "ci_high_vs_nonlinear_v": hi_nl,
                "gap_closed": gap_closed(full[k], nl, real),
                # the share of the headroom above nonlinear V (up to the V ceiling) captured,
                # where that headroom exceeds its noise (NaN otherwise: `headroom_captured`)
                "headroom_captured": headroom_captured(full[k], nl, ceiling, headroom_low),
                "delta_vs_distilled": d_gd,
                "ci_low_vs_distilled": lo_gd,
                "ci_high_vs_distilled": hi_gd,
                "below_majority": bool(full[k] < base["majority"]),
                "reg": fits[k].reg,
                "reg_source": fits[k].source,
            }
        )
    return rows
