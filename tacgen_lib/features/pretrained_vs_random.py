"""Is pretraining worth it? Pretrained vs random-init backbone of the same architecture.

A linear (logistic) probe on frozen features of each backbone, fitted on the train rows and
scored on the fixed test rows; the difference in accuracy gets a fixed-test bootstrap CI
(tacgen_lib.probes.bootstrap.fixed_test_bootstrap), so "pretraining helps" is a statement with an interval;
each accuracy gets its own CI on the same resamples (tacgen_lib.probes.score_ci.score_ci).

With `features.pretrain.epochs: 0` (the embedded default) no pretraining runs:
the "pretrained" backbone is the random-init one (`random_backbone`, same seed), Delta is 0 by
construction and the table reports what the frozen random-init features attain.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tacgen_lib.features.vit import random_backbone
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
from tacgen_lib.probes.logistic import fit_logistic
from tacgen_lib.probes.score_ci import score_ci

__all__ = ["pretrained_vs_random", "random_backbone"]


def pretrained_vs_random(
    pretrained: np.ndarray,
    random_init: np.ndarray,
    labels: np.ndarray,
    train: np.ndarray,
    test: np.ndarray,
    *,
    C_grid: Sequence[float],
    seed: int,
    n_resamples: int,
    n_folds: int = 3,
    sample_ids: np.ndarray | None = None,
) -> dict:
    """Accuracy of a logistic probe on each feature set and Δ = pretrained − random with a CI.

    pretrained, random_init: (N, d) features of the same N frames; labels: (N,) classes;
    train, test: row positions; C by `n_folds`-fold CV on the train rows (one draw of the folds).
    Returns random_accuracy, pretrained_accuracy (each with its bootstrap CI `*_ci_low`,
    `*_ci_high` on the resamples of Delta's), delta, ci_low, ci_high, p_gt0, the test chance
    level (majority class) and the chosen C of each probe.
    """
    ids_tr = None if sample_ids is None else sample_ids[train]
    ids_te = None if sample_ids is None else sample_ids[test]
    fits = {}
    preds = {}
    for name, feats in (("random", random_init), ("pretrained", pretrained)):
        probe = fit_logistic(
            feats[train], labels[train], C_grid, seed, n_folds=n_folds, repeats=1, sample_ids=ids_tr
        )
        fits[name] = probe
        preds[name] = probe.predict(feats[test], sample_ids=ids_te)
    boot = fixed_test_bootstrap(
        labels[test],
        preds["random"],
        preds["pretrained"],
        "accuracy",
        n_resamples=n_resamples,
        seed=seed,
    )
    cis = {
        name: score_ci("accuracy", labels[test], preds[name], n_resamples=n_resamples, seed=seed)[
            1:
        ]
        for name in ("random", "pretrained")
    }
    return {
        "random_accuracy": boot["v_score"],
        "random_ci_low": cis["random"][0],
        "random_ci_high": cis["random"][1],
        "pretrained_accuracy": boot["vt_score"],
        "pretrained_ci_low": cis["pretrained"][0],
        "pretrained_ci_high": cis["pretrained"][1],
        "delta": boot["delta"],
        "ci_low": boot["ci_low"],
        "ci_high": boot["ci_high"],
        "p_gt0": boot["p_gt0"],
        "n_train": int(len(train)),
        "n_test": int(len(test)),
        "n_classes": int(len(np.unique(labels))),
        "chance": float(np.max(np.unique(labels[test], return_counts=True)[1]) / len(test)),
        "C_random": fits["random"].C,
        "C_pretrained": fits["pretrained"].C,
    }
