"""The uncertainty of a knob's point: how much a setting's figure moves when only its seed does.

This module owns the new numerics of the knob sweeps (the rest is the stages' own code):

- `sd_interval`: the Monte Carlo spread of a figure over replicate seeds (sample sd) with its
  chi-square confidence interval (normal replicates), e.g. how far a bootstrap CI endpoint
  moves between bootstrap seeds at B resamples;
- `retrieval_bootstrap`: top-1 and median rank of paired retrieval, averaged over alignment
  seeds, with a percentile CI from resampling the test rows (the same resample for every
  seed, drawn by the probes' `resample_indices`);
- `replicate_seconds`: the cost of one run of a setting from its replicate jobs' benchmarks;
- `setting_seconds`: what one run of a setting costs (`Seconds`), from the benchmark files of
  its runs, the one place every knob's seconds are assembled.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tacgen_lib.probes.bootstrap import resample_indices
from tacgen_lib.runtime.benchmarks import Benchmark

__all__ = ["Seconds", "replicate_seconds", "retrieval_bootstrap", "sd_interval", "setting_seconds"]


@dataclass(frozen=True)
class Seconds:
    """What one run of a setting costs: wall and CPU seconds, from `n_jobs` benchmark files."""

    wall: float
    cpu: float
    n_jobs: int


def sd_interval(values: Sequence[float], confidence: float = 0.95) -> tuple[float, float, float]:
    """Sample standard deviation (ddof 1) of `values` and its chi-square CI.

    With k replicates, (k-1) s^2 / sigma^2 ~ chi2(k-1) for normal replicates, so sigma lies in
    [s sqrt((k-1)/chi2_{1-a/2}), s sqrt((k-1)/chi2_{a/2})]. Fewer than two finite values give
    NaN (no spread can be measured from one run).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"sd_interval: confidence must be in (0, 1), got {confidence}")
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size < 2:
        return math.nan, math.nan, math.nan
    from scipy import stats  # here, not at the top: the knob readers that never call this skip it

    k = v.size - 1
    sd = float(np.std(v, ddof=1))
    alpha = 1.0 - confidence
    lo = sd * math.sqrt(k / stats.chi2.ppf(1.0 - alpha / 2.0, k))
    hi = sd * math.sqrt(k / stats.chi2.ppf(alpha / 2.0, k))
    return sd, lo, hi


def retrieval_bootstrap(
    ranks: np.ndarray, n_resamples: int, seed: int, confidence: float = 0.95
) -> dict[str, float]:
    """Top-1 (fraction of rank 1) and median rank of retrieval, over the test rows, with
    percentile CIs from resampling those rows.

    ranks: (n_seeds, n_test) rank (1 = first) of each test row's positive, one row per
    alignment seed, columns the same test rows in the same order. Each figure is the mean
    over seeds of that seed's figure; a resample picks the same test rows for every seed, so
    the CI reflects the finite test set, the seeds' mean the training noise.
    Returns top1, top1_low, top1_high, median_rank, median_rank_low, median_rank_high; an
    interval that misses the full-test figure (possible for a median of ranks, which moves in
    whole steps) is widened to contain it.
    """
    r = np.asarray(ranks, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] < 1 or r.shape[0] < 1:
        raise ValueError(f"retrieval_bootstrap: ranks must be (n_seeds, n_test), got {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r < 1):
        raise ValueError("retrieval_bootstrap: ranks must be finite and >= 1")
    idx = resample_indices(r.shape[1], n_resamples, seed)
    hits = (r <= 1.0).astype(np.float64)
    top1 = hits[:, idx].mean(axis=2).mean(axis=0)  # (B,)
    med = np.median(r[:, idx], axis=2).mean(axis=0)  # (B,)
    a = (1.0 - confidence) / 2.0
    t_lo, t_hi = np.quantile(top1, [a, 1.0 - a])
    m_lo, m_hi = np.quantile(med, [a, 1.0 - a])
    t_full = float(hits.mean(axis=1).mean())
    m_full = float(np.median(r, axis=1).mean())
    return {
        "top1": t_full,
        "top1_low": float(min(t_lo, t_full)),
        "top1_high": float(max(t_hi, t_full)),
        "median_rank": m_full,
        "median_rank_low": float(min(m_lo, m_full)),
        "median_rank_high": float(max(m_hi, m_full)),
    }


def replicate_seconds(benchmarks: Sequence[Benchmark]) -> tuple[float, float, int]:
    """(wall, CPU seconds, n) of one run of a setting: the mean over its replicate jobs."""
    if not benchmarks:
        raise ValueError("replicate_seconds: no benchmark files")
    wall = float(np.mean([b.wall for b in benchmarks]))
    cpu = (
        float(np.nanmean([b.cpu for b in benchmarks]))
        if any(math.isfinite(b.cpu) for b in benchmarks)
        else math.nan
    )
    return wall, cpu, len(benchmarks)


def setting_seconds(runs: Sequence[Sequence[Benchmark]]) -> Seconds:
    """What one run of a setting costs, from its runs' benchmark files (one list per run: the
    jobs of one run add up). One run: its jobs' wall and CPU seconds summed. Several runs
    (replicate seeds, run only to measure a spread): the mean over runs of each run's sums
    (`replicate_seconds`). `n_jobs` counts every file read."""
    if len(runs) == 1:
        jobs = runs[0]
        return Seconds(sum(b.wall for b in jobs), sum(b.cpu for b in jobs), len(jobs))
    per_run = [
        Benchmark(
            sum(b.wall for b in jobs), sum(b.cpu for b in jobs), max(b.max_rss_mb for b in jobs)
        )
        for jobs in runs
    ]
    wall, cpu, _ = replicate_seconds(per_run)
    return Seconds(wall, cpu, sum(len(jobs) for jobs in runs))
