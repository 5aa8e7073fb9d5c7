"""One grid cell of the alignment stage: `cell_ids` (the corpus's train/val/test rows, the train
rows cut to `n_train` by `train_subset`) and `fit_cell` (split guard, `fit_heads`, retrieval on
the held-out test rows with each test row's rank, the training curve as a table).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd

from tacgen_lib.align.heads import AlignResult, project
from tacgen_lib.align.retrieval import (
    CHANCE_COLUMNS,
    RETRIEVAL_METRICS,
    paired_retrieval,
    retrieval_ranks,
)
from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.align.train import fit_heads
from tacgen_lib.corpus.splits import assert_trainable, ids_in_split
from tacgen_lib.io import edges

_RETRIEVAL_KEYS = (*RETRIEVAL_METRICS, *CHANCE_COLUMNS)


def parse_n_train(text: str | int) -> int | Literal["all"]:
    """A training size as written in config or a path: ``"all"`` or an integer >= 2."""
    if text == "all":
        return "all"
    try:
        n = int(text)
    except (TypeError, ValueError):
        n = -1
    if n < 2 or str(n) != str(text).strip():
        raise ValueError(f"n_train must be 'all' or an integer >= 2, got {text!r}")
    return n


def train_subset(
    train_ids: Sequence[str] | np.ndarray, n_train: int | str, seed: int
) -> np.ndarray:
    """The alignment-train rows of one cell: all train ids, or a seeded random subset of them.

    Ids are sorted first, so the result depends only on the set of ids, `n_train` and `seed`.
    For one seed the subsets are nested (the first n of one seeded permutation), so a larger
    N adds rows to a smaller one. Returned sorted.
    """
    ids = np.sort(np.asarray(list(train_ids), dtype=object))
    n = parse_n_train(n_train)
    if n == "all":
        return ids
    if n > ids.size:
        raise ValueError(
            f"n_train={n} but the train split has only {ids.size} rows; "
            "lower align.n_train or use 'all'"
        )
    order = np.random.default_rng(seed).permutation(ids.size)
    return np.sort(ids[order[:n]])


def cell_ids(
    splits: pd.DataFrame, *, corpus: str, n_train: int | str, seed: int
) -> dict[str, np.ndarray]:
    """train (cut to `n_train` by `train_subset`), val and test sample ids of one corpus."""
    out = {name: np.sort(ids_in_split(splits, name, corpus)) for name in ("train", "val", "test")}
    for name, ids in out.items():
        if ids.size == 0:
            raise ValueError(
                f"corpus {corpus!r} has no {name!r} rows in the split edge; alignment needs "
                "train, val (early stopping) and test (retrieval) rows: check config splits"
            )
    out["train"] = train_subset(out["train"], n_train, seed)
    return out


@dataclass
class CellFit:
    """What `fit_cell` returns: the fit, its test-split retrieval metrics, its curve table and
    the test rows' ranks (`sample_id`, `rank_v2t`, `rank_t2v`: what a bootstrap over the test
    rows resamples)."""

    result: AlignResult
    metrics: dict[str, Any]
    curve: pd.DataFrame
    ranks: pd.DataFrame


def fit_cell(
    vision: edges.Edge,
    tactile: edges.Edge,
    splits: pd.DataFrame,
    ids: dict[str, Sequence[str] | np.ndarray],
    *,
    tau: float,
    seed: int,
    settings: AlignSettings,
    rule: str = "train_heads",
    progress: Callable[[str], Any] | None = None,
    device: Any,
) -> CellFit:
    """Train one alignment cell and evaluate it on held-out pairs (paper eq. 1, retrieval).

    vision, tactile: the corpus's feature edges (keyed by sample_id); `settings.feature`
    names the vector column both use (``vit`` or ``pixel``). ids: {"train", "val", "test"} sample ids
    (from `cell_ids`). The split guard runs first: `assert_trainable` refuses any train id not
    in the train split and any validation id not in the val split (validation rows only steer
    early stopping), naming the rule and the sample_id. Rows are joined on sample_id, never on
    order. `settings` and `device` (a torch device or its name) are passed on to `fit_heads`.

    metrics: `paired_retrieval` of the projected test rows (top1/top5 both ways, median ranks,
    chance levels), n_test, n_train_rows, n_val, best-step validation loss, best_step,
    steps_run, stopped_early. curve: one row per evaluation, keyed by ``eval`` = "step~<k>".
    ranks: each test row's retrieval rank V→T and T→V (`retrieval_ranks`), keyed by sample_id.
    """
    train_ids = list(ids["train"])
    val_ids = list(ids["val"])
    test_ids = list(ids["test"])
    assert_trainable(train_ids, splits, rule=rule, allowed=("train",))
    assert_trainable(val_ids, splits, rule=rule, allowed=("val",))
    held = set(test_ids) & (set(train_ids) | set(val_ids))
    if held:
        raise ValueError(
            f"rule {rule}: sample_id {sorted(held)[0]!r} is both a test row and a training row"
        )
    feature = settings.feature
    for edge in (vision, tactile):
        if feature not in edge.vectors:
            raise edges.EdgeError(
                f"{edge.path}: no vector column {feature!r} (has: {sorted(edge.vectors)}); "
                "align.features must name a column of the feature edges"
            )
    fit_ids = train_ids + val_ids
    v = vision.subset(fit_ids).vectors[feature]
    t = tactile.subset(fit_ids).vectors[feature]
    n_tr = len(train_ids)
    result = fit_heads(
        v,
        t,
        np.arange(n_tr),
        np.arange(n_tr, len(fit_ids)),
        tau=tau,
        seed=seed,
        settings=settings,
        progress=progress,
        device=device,
    )
    z_v, z_t = project(
        result,
        vision.subset(test_ids).vectors[feature],
        tactile.subset(test_ids).vectors[feature],
        device=device,
    )
    retrieval = paired_retrieval(z_v, z_t)
    metrics: dict[str, Any] = {
        "budget": str(result.config["budget"]),
        "val_loss": float(result.best_val_loss),
        **{k: float(retrieval[k]) for k in _RETRIEVAL_KEYS},
        "n_test": int(retrieval["n"]),
        "n_train_rows": n_tr,
        "n_val": len(val_ids),
        "best_step": int(result.best_step),
        "steps_run": int(result.steps_run),
        "stopped_early": bool(result.stopped_early),
    }
    curve = pd.DataFrame(
        [
            {
                "eval": f"step~{int(c['step'])}",
                "step": int(c["step"]),
                "epoch": float(c["epoch"]),
                "lr": float(c["lr"]),
                "train_loss": np.nan if c["train_loss"] is None else float(c["train_loss"]),
                "val_loss": float(c["val_loss"]),
                "val_top1": float(c["val_top1"]),
            }
            for c in result.curve
        ]
    )
    ranks = pd.DataFrame(
        {
            "sample_id": test_ids,
            "rank_v2t": retrieval_ranks(z_v, z_t).astype(np.int64),
            "rank_t2v": retrieval_ranks(z_t, z_v).astype(np.int64),
        }
    )
    return CellFit(result=result, metrics=metrics, curve=curve, ranks=ranks)
