"""The regime's arms for its report page (`tacgen_lib.report.regime`) and figures
(`tacgen_lib.report.regime_figures`): the label a reader sees for each (arm, probe), the
ladder's rungs in words, and the rows of one arm.
"""

from __future__ import annotations

import pandas as pd

__all__ = [
    "ARM_LABELS",
    "NOT_BUILT_ON_V",
    "RUNG_LABELS",
    "arm_rows",
    "gains",
]

#: The ladder's rungs in words, top to bottom (`generate.ladder.LADDER`).
RUNG_LABELS = {
    "look_oracle": "A0 look oracle",
    "knn": "A1 kNN in V",
    "ridge": "ridge V→T",
    "kernel_ridge": "kernel ridge V→T",
    "gen_mean": "A2 diffusion mean",
    "v_tgen": "A3 one diffusion sample",
}

#: (arm, probe) -> the label a reader sees.
ARM_LABELS = {
    ("v", "linear"): "V (linear)",
    ("v", "nonlinear"): "V (nonlinear)",
    **{
        (rung, probe): f"V + T_gen {label} ({probe})"
        for rung, label in RUNG_LABELS.items()
        for probe in ("linear", "nonlinear")
    },
    ("v_tgen_shuffled", "linear"): "V + T_gen, shuffled pool (linear)",
    ("distilled", "linear"): "distillation, V only (linear)",
    ("distilled", "nonlinear"): "distillation, V only (nonlinear)",
    ("v_treal", "linear"): "V + real T (linear)",
    ("v_ceiling", "linear"): "V ceiling, every label (linear)",
    ("v_ceiling", "nonlinear"): "V ceiling, every label (nonlinear)",
    ("vision_ceiling", "oracle"): "vision ceiling (oracle)",
}

#: Arms that are no function of V and the labelled rows alone: they use the corpus's metadata
#: (the look oracle, the vision ceiling), every label (the V ceiling) or real touch.
NOT_BUILT_ON_V = ("look_oracle", "v_treal", "v_ceiling", "vision_ceiling")


def arm_rows(frame: pd.DataFrame, arm: str, probe: str) -> pd.DataFrame:
    """The rows of one (arm, probe) of a regime summary or `seed_view`."""
    return frame[(frame["arm"] == arm) & (frame["probe"] == probe)]


def gains(r: pd.Series) -> bool:
    """A `report.regime.seed_view` row gains over nonlinear V: the replicates' interval of its
    Delta, read as one (``rep_low_vs_nonlinear_v``, `claims.seeds_interval`: every replicate's
    CI and, from three on, the mean's t-interval over them), lies above 0. The rule the ladder's
    verdict and the curve against the pool size decide by."""
    return bool(r["rep_low_vs_nonlinear_v"] > 0)
