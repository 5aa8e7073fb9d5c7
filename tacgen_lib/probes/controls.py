"""Controls of the probe gain Delta: the checks that could show a V+T gain false.

This module owns the controls of one comparison (`PairedRows`: V, T and y of the train and
test rows, and the fusion), each B refits of the comparison's probes at their CV-chosen
regularisers through one path, the probe's ``refit_many`` (`refits.Refits`):

- `tactile_permutation_control`: break the V-T pairing of the training rows (the paper's
  control: the V+T probe is refitted on permuted training T and scored on the intact test
  pairs);
- `label_permutation_control`: break the X-y link within the training rows;
- `random_feature_control`: T replaced by dimension-matched Gaussian features;
- `train_resample_diagnostic`: variability from the training data, both probes refitted on
  bootstrap resamples of the training rows (the fixed-test bootstrap holds them fixed);

and `paper_criterion`: Delta >= 0.03, CI lower bound > 0, Delta_ctrl < Delta.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from tacgen_lib.probes.bootstrap import resample_indices
from tacgen_lib.probes.fusion import fuse
from tacgen_lib.probes.metrics import Metric, check_metric, score_rows
from tacgen_lib.probes.objective import DesignBlock
from tacgen_lib.probes.refits import FixedProbe, Refits

__all__ = [
    "PairedRows",
    "label_permutation_control",
    "paper_criterion",
    "permutations",
    "random_feature_control",
    "tactile_permutation_control",
    "train_resample_diagnostic",
]


@dataclass(frozen=True)
class PairedRows:
    """What a comparison's controls see: V and T features and the target on the training
    and test rows (row i of V, T and y is one sample), and how V and T are fused."""

    v_train: np.ndarray
    t_train: np.ndarray
    y_train: np.ndarray
    v_test: np.ndarray
    t_test: np.ndarray
    y_test: np.ndarray
    fusion: str = "concat"

    @cached_property
    def vt_train(self) -> np.ndarray:
        """The V+T probe's training design, fuse(V, T)."""
        return fuse(self.fusion, self.v_train, self.t_train)

    @cached_property
    def vt_test(self) -> np.ndarray:
        return fuse(self.fusion, self.v_test, self.t_test)


def _one(x_train: np.ndarray, x_test: np.ndarray, y: np.ndarray, **kw) -> Refits:
    """Refits of a one-block design (V alone, or an already fused V+T)."""
    return Refits((DesignBlock(x_train),), (DesignBlock(x_test),), y, **kw)


def _t_replaced(
    rows: PairedRows,
    v: tuple[np.ndarray, np.ndarray],
    t: tuple[DesignBlock, DesignBlock],
    *,
    probe: FixedProbe,
    probe_v: FixedProbe | None,
    metric: Metric,
) -> dict:
    """Delta of a control that replaces T per problem (permuted, or random draws): the V+T
    probe refitted on fuse(V, T) for every problem of the replaced blocks `t` (train, test),
    the V probe (``probe_v``, default ``probe``) once on all training rows of `v` (train,
    test). The V probe goes through the batched solver (B = 1) when the V+T side does, so both
    sides of every Delta share a solver."""
    v_train, v_test = v
    refits = Refits(
        (DesignBlock(v_train), t[0]),
        (DesignBlock(v_test), t[1]),
        np.asarray(rows.y_train),
        fusion=rows.fusion,
    )
    probe_v = probe_v or probe
    batched = probe.batches(refits)
    y_train, y_test = np.asarray(rows.y_train), np.asarray(rows.y_test)
    v_refit = probe_v.refit_many(_one(v_train, v_test, y_train), batched=batched)
    v_score = float(score_rows(metric, y_test, v_refit.pred)[0])
    refit = probe.refit_many(refits, batched=batched)
    vt = score_rows(metric, y_test, refit.pred)
    deltas = vt - v_score
    return {
        "v_score": v_score,
        "vt_scores": vt,
        "deltas": deltas,
        "delta_ctrl": float(deltas.mean()),
        "solver": refit.solver,
        **_summary(deltas),
    }


def _summary(deltas: np.ndarray) -> dict:
    return {
        "delta_mean": float(np.mean(deltas)),
        "delta_sd": float(np.std(deltas, ddof=1)) if deltas.size > 1 else 0.0,
        "delta_q025": float(np.quantile(deltas, 0.025)),
        "delta_q975": float(np.quantile(deltas, 0.975)),
    }


def permutations(n: int, n_perm: int, rng: np.random.Generator) -> np.ndarray:
    """(n_perm, n) independent permutations of range(n), drawn in one batch."""
    return np.argsort(rng.random((n_perm, n)), axis=1, kind="stable")


def train_resample_diagnostic(
    rows: PairedRows,
    *,
    probe_v: FixedProbe,
    probe_vt: FixedProbe,
    metric: Metric,
    n_resamples: int,
    seed: int,
) -> dict:
    """Refit both probes on bootstrap resamples of the TRAINING rows; score on the full test.

    Shows how much Delta moves with the training sample (the fixed-test bootstrap holds the
    probes fixed). Probes are refitted at their fixed regulariser (e.g. `FixedRidge(lam)`).
    Returns per-resample v_scores, vt_scores, deltas and their summary.
    """
    check_metric(metric)
    y_train, y_test = np.asarray(rows.y_train), np.asarray(rows.y_test)
    idx = resample_indices(len(y_train), n_resamples, seed)
    vt = _one(rows.vt_train, rows.vt_test, y_train, rows=idx)
    batched = probe_vt.batches(vt)  # the V side follows, so a Delta never mixes solvers
    v = _one(rows.v_train, rows.v_test, y_train, rows=idx)
    v_s = score_rows(metric, y_test, probe_v.refit_many(v, batched=batched).pred)
    vt_s = score_rows(metric, y_test, probe_vt.refit_many(vt, batched=batched).pred)
    deltas = vt_s - v_s
    return {
        "v_scores": v_s,
        "vt_scores": vt_s,
        "deltas": deltas,
        "n_resamples": n_resamples,
        **_summary(deltas),
    }


def tactile_permutation_control(
    rows: PairedRows,
    *,
    probe: FixedProbe,
    metric: Metric,
    n_permutations: int,
    seed: int,
    probe_v: FixedProbe | None = None,
) -> dict:
    """Delta when the V+T probe is refitted on permuted TRAINING T (the paper's control).

    For each permutation the V+T probe is refitted on fuse(V, T[perm]) over the training rows
    at its fixed regulariser and scored on the test rows with their own, intact T (the test
    block is never permuted: the probe must show that what it learned from the pairing is
    lost, on the same test pairs as the main comparison). The V probe (``probe_v``, default
    ``probe``) is unaffected. ``delta_ctrl`` = mean Delta over permutations. Permutations of
    the training rows are drawn in one batch (B, n_train) from ``default_rng(seed)``; no
    test permutation is drawn (an earlier version drew a (B, n_test) batch after it, and the test
    pairs were permuted too).
    The probe's ``refit_many`` solves them together where it can (ridge with ``concat`` and
    p >= n_train: the kernel path; logistic with ``concat``: the batched solver) and refits
    one at a time otherwise.
    """
    check_metric(metric)
    v_train, t_train = np.asarray(rows.v_train, np.float64), np.asarray(rows.t_train, np.float64)
    v_test, t_test = np.asarray(rows.v_test, np.float64), np.asarray(rows.t_test, np.float64)
    if v_train.shape[0] != t_train.shape[0] or v_test.shape[0] != t_test.shape[0]:
        raise ValueError("tactile_permutation_control: V and T must have the same rows")
    rng = np.random.default_rng(seed)
    perm_tr = permutations(v_train.shape[0], n_permutations, rng)
    t = DesignBlock(t_train, perm_tr), DesignBlock(t_test)  # test pairs intact
    out = _t_replaced(rows, (v_train, v_test), t, probe=probe, probe_v=probe_v, metric=metric)
    return {**out, "n_permutations": n_permutations}


def label_permutation_control(
    rows: PairedRows,
    *,
    probe_v: FixedProbe,
    probe_vt: FixedProbe,
    metric: Metric,
    n_permutations: int,
    seed: int,
) -> dict:
    """Scores and Delta when y is permuted within the training rows (X-y link broken).

    Test labels stay true. Each probe solves all permuted targets together where it can
    (ridge: one factorisation for every target; logistic: the batched solver).
    """
    check_metric(metric)
    y_train, y_test = np.asarray(rows.y_train), np.asarray(rows.y_test)
    rng = np.random.default_rng(seed)
    y_perm = y_train[permutations(y_train.size, n_permutations, rng)]  # (B, n)
    v_s = score_rows(
        metric, y_test, probe_v.refit_many(_one(rows.v_train, rows.v_test, y_perm)).pred
    )
    vt = _one(rows.vt_train, rows.vt_test, y_perm)
    vt_s = score_rows(metric, y_test, probe_vt.refit_many(vt).pred)
    deltas = vt_s - v_s
    return {
        "v_scores": v_s,
        "vt_scores": vt_s,
        "deltas": deltas,
        "v_score_mean": float(v_s.mean()),
        "vt_score_mean": float(vt_s.mean()),
        "n_permutations": n_permutations,
        **_summary(deltas),
    }


def random_feature_control(
    rows: PairedRows,
    *,
    probe: FixedProbe,
    metric: Metric,
    n_draws: int,
    seed: int,
    probe_v: FixedProbe | None = None,
) -> dict:
    """Delta when T is replaced by Gaussian features of the same dimension (seeded).

    Each draw gives every train and test row an independent N(mu_j, sd_j^2) vector, with
    mu_j, sd_j the per-column mean and SD of the TRAINING tactile features, so the random
    block has T's dimension and scale (the ridge penalty treats it like T) and no content.
    Draws are made train then test, draw after draw, from ``default_rng(seed)``.
    """
    check_metric(metric)
    t_train = np.asarray(rows.t_train, np.float64)
    mu, sd = t_train.mean(axis=0), t_train.std(axis=0)
    rng = np.random.default_rng(seed)
    n_test, d = len(rows.y_test), t_train.shape[1]
    r_tr, r_te = np.empty((n_draws, *t_train.shape)), np.empty((n_draws, n_test, d))
    for j in range(n_draws):
        r_tr[j] = mu + sd * rng.standard_normal(t_train.shape)
        r_te[j] = mu + sd * rng.standard_normal((n_test, d))
    v, t = (rows.v_train, rows.v_test), (DesignBlock(r_tr), DesignBlock(r_te))
    out = _t_replaced(rows, v, t, probe=probe, probe_v=probe_v, metric=metric)
    return {**out, "n_draws": n_draws}


def paper_criterion(
    delta: float, ci_low: float, delta_ctrl: float, min_delta: float = 0.03
) -> bool:
    """The paper's claim test: Delta >= min_delta, CI lower bound > 0 and Delta_ctrl < Delta."""
    vals = {"delta": delta, "ci_low": ci_low, "delta_ctrl": delta_ctrl, "min_delta": min_delta}
    for name, v in vals.items():
        if not np.isfinite(v):
            raise ValueError(f"paper_criterion: {name} is {v!r}; every input must be finite")
    return bool(delta >= min_delta and ci_low > 0.0 and delta_ctrl < delta)
