"""What the simulation and features knobs buy: each setting's metrics with their uncertainty,
and the knob's cost-of-accuracy points (`tacgen_lib.cost.points`) from its jobs' benchmarks.

Simulation knobs (presses per sample, tactile render resolution) re-simulate a reduced copy of
a paired corpus per setting; for each copy this module measures the width of the p05-p95 force
band (`force_band_width`); the probes are the probes stage's own (`tacgen_lib.cost.readers`).

Features knobs (backbone input size, width, pretraining epochs) read the pretrained-vs-random
table of `tacgen_lib.features.pretrained_vs_random` (`features_metrics`).

`knob_points` turns the settings of one knob into `POINT_COLUMNS` rows: seconds are summed over
the `benchmark:` files of the jobs each setting needed, never read from an edge.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tacgen_lib.cost.points import POINT_COLUMNS, check_points
from tacgen_lib.probes.bootstrap import resample_indices
from tacgen_lib.probes.metrics import Metric
from tacgen_lib.runtime.benchmarks import Benchmark

__all__ = [
    "BAND_WIDTH",
    "FRAMES_PER_S",
    "METRIC_COLUMNS",
    "probe_metric_ids",
    "features_metric_ids",
    "KnobSetting",
    "force_band_width",
    "features_metrics",
    "knob_points",
    "metric_row",
    "PERCENTILE_CI",
]

#: Columns of a setting's metrics edge (key `metric_id`, the metric's name).
METRIC_COLUMNS = ["metric_id", "value", "ci_low", "ci_high", "uncertainty"]

#: The simulation knobs' metrics that are not probes.
BAND_WIDTH = "force band p05–p95 width (N)"
FRAMES_PER_S = "frames/s (simulate job, one core)"

PERCENTILE_CI = "95 % percentile bootstrap CI over the test rows ({b} resamples)"


def force_band_width(
    p05: np.ndarray, p95: np.ndarray, *, n_resamples: int, seed: int
) -> tuple[float, float, float]:
    """Mean width of the p05-p95 force band over samples (N) and its 95 % bootstrap CI over
    samples: (mean, low, high). With few presses the percentiles of a handful of jittered
    presses under-state the band; more presses converge on it."""
    lo_f, hi_f = np.asarray(p05, dtype=np.float64), np.asarray(p95, dtype=np.float64)
    if lo_f.ndim != 1 or lo_f.shape != hi_f.shape or lo_f.size == 0:
        raise ValueError(
            f"force_band_width: p05 {lo_f.shape} and p95 {hi_f.shape} must be equal 1-D"
        )
    width = hi_f - lo_f
    if not np.isfinite(width).all() or (width < 0).any():
        i = int(np.flatnonzero(~(np.isfinite(width) & (width >= 0)))[0])
        raise ValueError(f"force_band_width: row {i} has p05 {lo_f[i]} above p95 {hi_f[i]}")
    idx = resample_indices(width.size, n_resamples, seed)
    means = width[idx].mean(axis=1)
    lo, hi = np.quantile(means, [0.025, 0.975])
    return float(width.mean()), float(lo), float(hi)


def probe_metric_ids(target: str, metric: Metric) -> tuple[str, str]:
    """Names of a probe's two metrics in `probe_metrics`: (score of V+T, Delta V+T - V)."""
    label = "R²" if metric == "r2" else "accuracy"
    return f"{target} {label} V+T", f"{target} Δ{label} V+T − V"


def features_metric_ids(modality: str, target: str) -> tuple[str, str]:
    """Names of a modality's two metrics in `features_metrics`: (Delta pretrained - random,
    accuracy of the backbone in use)."""
    return (
        f"{modality} {target} Δaccuracy pretrained − random",
        f"{modality} {target} accuracy",
    )


def metric_row(metric_id: str, value: float, lo: float, hi: float, uncertainty: str) -> dict:
    """One row of `METRIC_COLUMNS`."""
    return {
        "metric_id": metric_id,
        "value": value,
        "ci_low": lo,
        "ci_high": hi,
        "uncertainty": uncertainty,
    }


def features_metrics(table: pd.DataFrame, *, pretraining: bool, n_resamples: int) -> list[dict]:
    """Rows of `METRIC_COLUMNS` from a pretrained-vs-random table (one row per modality):
    "<modality> <target> Δaccuracy pretrained − random" and "<modality> <target> accuracy"
    of the backbone the config uses (the pretrained one when `pretraining`, else the
    random-init one), each with its fixed-test bootstrap CI."""
    need = {
        "modality",
        "target",
        "delta",
        "ci_low",
        "ci_high",
        "pretrained_accuracy",
        "pretrained_ci_low",
        "pretrained_ci_high",
        "random_accuracy",
        "random_ci_low",
        "random_ci_high",
    }
    missing = sorted(need - set(table.columns))
    if missing:
        raise ValueError(f"features_metrics: the pretrained-vs-random table lacks {missing}")
    how = PERCENTILE_CI.format(b=n_resamples)
    used = "pretrained" if pretraining else "random"
    out = []
    for r in table.sort_values("modality").itertuples(index=False):
        delta_id, acc_id = features_metric_ids(r.modality, r.target)
        out.append(metric_row(delta_id, r.delta, r.ci_low, r.ci_high, how))
        out.append(
            metric_row(
                acc_id,
                getattr(r, f"{used}_accuracy"),
                getattr(r, f"{used}_ci_low"),
                getattr(r, f"{used}_ci_high"),
                how,
            )
        )
    return out


@dataclass(frozen=True)
class KnobSetting:
    """One setting of a knob: its number (log x-axis), its label, whether it is the config's
    own, the metrics it bought (`METRIC_COLUMNS` frame) and the benchmarks of its jobs."""

    setting: float
    label: str
    is_default: bool
    metrics: pd.DataFrame
    benchmarks: Sequence[Benchmark]


def knob_points(
    knob: str,
    stage: str,
    settings: Sequence[KnobSetting],
    metrics: Sequence[str] | None = None,
) -> pd.DataFrame:
    """The knob's cost points (`POINT_COLUMNS`, checked): one row per setting and metric.

    metrics: which metric_ids to keep, in order (None: all of each setting's); a setting
    lacking one raises.
    wall_s / cpu_s: sums over the setting's benchmarks, n_jobs their count.
    """
    if not settings:
        raise ValueError(f"knob {knob!r}: no settings")
    labels = [s.label for s in settings]
    if len(set(labels)) != len(labels):
        raise ValueError(f"knob {knob!r}: duplicate settings {labels}")
    rows = []
    for s in settings:
        if not s.benchmarks:
            raise ValueError(f"knob {knob!r} setting {s.label!r}: no benchmark files")
        frame = s.metrics.set_index("metric_id")
        wanted = list(frame.index) if metrics is None else list(metrics)
        missing = [m for m in wanted if m not in frame.index]
        if missing:
            raise ValueError(
                f"knob {knob!r} setting {s.label!r}: metrics {missing} not measured "
                f"(have {list(frame.index)})"
            )
        found = [dict(frame.loc[m], metric_id=m) for m in wanted]
        wall = float(sum(b.wall for b in s.benchmarks))
        cpu = float(sum(b.cpu for b in s.benchmarks))
        for m in found:
            rows.append(
                {
                    "knob": knob,
                    "stage": stage,
                    "setting": float(s.setting),
                    "label": s.label,
                    "is_default": bool(s.is_default),
                    "metric": m["metric_id"],
                    "value": float(m["value"]),
                    "ci_low": float(m["ci_low"]),
                    "ci_high": float(m["ci_high"]),
                    "uncertainty": str(m["uncertainty"]),
                    "wall_s": wall,
                    "cpu_s": cpu,
                    "n_jobs": len(s.benchmarks),
                }
            )
    return check_points(pd.DataFrame(rows, columns=POINT_COLUMNS), source=f"knob {knob!r}")
