"""Probe robustness: the headline Deltas under protocol variants, training sizes and splits.

This module owns the two analyses of the robustness runs that are not a protocol variant (their
settings, `RobustnessSettings` of config ``probes.robustness``, live in the import-light
`probes.settings`, which the Snakefile reads):

- `training_size_sweep`: the headline comparison (raw V vs V+T, ``concat``,
  heads' tactile variant) refitted on nested subsets of the training rows, n in a configured
  grid, for several subset seeds; each point has its fixed-test bootstrap CI on the full test
  rows. Subsets are nested (a smaller n is a prefix of a larger one for the same seed) and,
  for class targets, stratified at every prefix (`subsets.nested_subsets`).
- the held-out-scale diagnosis (`rows.family_rows` with ``within_scale``,
  `subsets.within_scale_split`). The appearance-controlled corpus is split
  by scale (train 0.15/0.20, test 0.25), so its mass probe extrapolates to an unseen scale.
  This re-splits the TRAINING rows only (train + val; the held-out test rows are never used)
  at random within each scale, so a probe on it asks "does touch carry mass" without asking
  "does the fit extrapolate to a new scale". The two results sit side by side in the report.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from tacgen_lib.probes.compare import MAIN_STATISTICS, compare, comparison_frame
from tacgen_lib.probes.rows import FamilyRows
from tacgen_lib.probes.settings import ProbeSettings, RobustnessSettings
from tacgen_lib.probes.subsets import nested_subsets

__all__ = ["SIZE_COLUMNS", "RobustnessSettings", "training_size_sweep"]


# --------------------------------------------------------------------------- subsets


def _subset(rows: FamilyRows, idx: np.ndarray) -> FamilyRows:
    vis = None if rows.visible_train is None else rows.visible_train[idx]
    return replace(
        rows, train_ids=rows.train_ids[idx], y_train=rows.y_train[idx], visible_train=vis
    )


#: Columns of the training-size edge (one row per family, subset seed and n).
SIZE_COLUMNS = (
    "row_id",
    "family",
    "corpus",
    "target",
    "metric",
    "protocol",
    "subset_seed",
    "n_requested",
    "n_train",
    "n_test",
    "status",
    *MAIN_STATISTICS,
    "notes",
)


def training_size_sweep(
    family: str,
    rows: FamilyRows,
    *,
    vision: tuple[np.ndarray, np.ndarray],
    tactile: tuple[np.ndarray, np.ndarray],
    settings: ProbeSettings,
    sizes: Sequence[int | str],
    seeds: Sequence[int],
    progress: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Raw V vs V+T (concat) at every training size and subset seed; one row per point.

    The subset seed also seeds the CV folds and the bootstrap of that point, so the spread
    over seeds includes them. Test rows are the family's full test split at every point.
    A point whose probe cannot be fitted (a class left with one row) is a ``failed`` row.
    """
    say = progress or (lambda _m: None)
    labels = rows.y_train if settings.kind == "logistic" else None
    out = []
    for seed in seeds:
        for size, idx in nested_subsets(rows.n_train, sizes, seed, labels=labels).items():
            sub = _subset(rows, idx)
            s = replace(settings, seed=int(seed))
            key = f"{family}|n~{size}|s~{seed}"
            base = {
                "row_id": key,
                "family": family,
                "corpus": rows.corpus,
                "target": rows.target,
                "metric": settings.metric,
                "protocol": settings.protocol,
                "subset_seed": int(seed),
                "n_requested": str(size),
                "n_train": int(idx.size),
                "n_test": rows.n_test,
            }
            try:
                res = compare(
                    vision[0][idx],
                    vision[1],
                    tactile[0][idx],
                    tactile[1],
                    sub,
                    "concat",
                    s,
                    controls=False,
                )
            except ValueError as exc:
                out.append(
                    {**base, "status": "failed", "notes": f"probe could not be fitted: {exc}"}
                )
                say(f"{key}: failed ({exc})")
                continue
            m = res.main
            out.append({**base, "status": "ok", **{c: m[c] for c in MAIN_STATISTICS}, "notes": ""})
            say(f"{key}: delta {m['delta']:+.3f} [{m['ci_low']:+.3f}, {m['ci_high']:+.3f}]")
    return comparison_frame(out, SIZE_COLUMNS)
