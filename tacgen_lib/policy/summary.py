"""The policy stage's summary tables (rule aggregate_policy), from the rollout edges.

- `summarise`: one row per cell (condition x hidden x epochs x seed) with n_episodes, success
  and its 95 % bootstrap CI, failure-mode counts and the median grip force (no wall times:
  they come from benchmark files and go only into the report's cost table);
- `deltas`: each condition against `v` (the matched-capacity, same-seed V-only policy, or the
  first main V cell for the references) on the same held-out episodes, with the paired
  bootstrap CI;
- `sweep`: the V-only capacity sweep with the fraction of the V -> V+T gap each cell closes,
  beside the vision-only ceiling (`oracle.vision_ceiling_success`: the bound from the task's
  generative process) and the ceiling force's success rolled out on the held-out episodes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import pandas as pd

from tacgen_lib.policy import oracle
from tacgen_lib.policy.evaluate import failure_counts, gap_closed, paired_delta_ci, success_ci
from tacgen_lib.policy.policy_cells import Cell, cell_name, main_cells, sweep_cells
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.policy.task import FAILURE_MODES

__all__ = ["summarise", "deltas", "sweep"]

#: seed offset of the episodes the vision-only ceiling is averaged over (a stream apart from
#: the demonstrations' and the held-out episodes')
CEILING_SEED = 7_000_019

SUMMARY_COLUMNS = [
    "cell",
    "condition",
    "hidden",
    "epochs",
    "seed",
    "n_episodes",
    "success",
    "ci_low",
    "ci_high",
    *FAILURE_MODES[1:],
    "median_force",
]


def _success(rollouts: Mapping[str, pd.DataFrame], cell: Cell) -> pd.Series:
    r = rollouts[cell_name(cell)]
    return r.set_index("episode_id")["success"].sort_index()


def summarise(
    rollouts: Mapping[str, pd.DataFrame],
    cells: Sequence[Cell],
    settings: PolicySettings,
) -> pd.DataFrame:
    rows = []
    for cell in cells:
        name = cell_name(cell)
        r = rollouts[name]
        s, lo, hi = success_ci(r["success"].to_numpy(), settings.bootstrap, settings.seed)
        counts = failure_counts(r["mode"].to_numpy())
        rows.append(
            {
                "cell": name,
                "condition": cell[0],
                "hidden": cell[1],
                "epochs": cell[2],
                "seed": cell[3],
                "n_episodes": len(r),
                "success": s,
                "ci_low": lo,
                "ci_high": hi,
                **{m: counts[m] for m in FAILURE_MODES[1:]},
                "median_force": float(r["grip_force"].median()),
            }
        )
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


def deltas(rollouts: Mapping[str, pd.DataFrame], settings: PolicySettings) -> pd.DataFrame:
    """Δsuccess of every main cell against V of the same seed (references: the first seed's V)."""
    rows = []
    mains = main_cells(settings)
    v_of = {c[3]: c for c in mains if c[0] == "v"}
    first_v = next(c for c in mains if c[0] == "v")
    for cell in mains:
        if cell[0] == "v":
            continue
        ref = v_of.get(cell[3], first_v)
        a, b = _success(rollouts, cell), _success(rollouts, ref)
        if not a.index.equals(b.index):
            raise ValueError(
                f"{cell_name(cell)} and {cell_name(ref)} were not rolled out on the same episodes"
            )
        d, lo, hi = paired_delta_ci(a.to_numpy(), b.to_numpy(), settings.bootstrap, settings.seed)
        rows.append(
            {
                "row_id": cell_name(cell),
                "condition": cell[0],
                "seed": cell[3],
                "reference": cell_name(ref),
                "n_episodes": len(a),
                "delta": d,
                "ci_low": lo,
                "ci_high": hi,
            }
        )
    return pd.DataFrame(rows)


def sweep(summary: pd.DataFrame, settings: PolicySettings) -> pd.DataFrame:
    """The V-only sweep cells (mean success over seeds per H x E) and the gap each closes."""
    cells = sweep_cells(settings)
    names = [cell_name(c) for c in cells]
    s = summary.set_index("cell").loc[names].reset_index()
    by = s.groupby(["hidden", "epochs"], as_index=False).agg(
        success=("success", "mean"), sd=("success", "std"), seeds=("seed", "count")
    )
    main = summary[summary["cell"].isin([cell_name(c) for c in main_cells(settings)])]
    v = float(main.loc[main["condition"] == "v", "success"].mean())
    vt = float(main.loc[main["condition"] == "vt_aligned", "success"].mean())
    rolled = float(main.loc[main["condition"] == "vision_ceiling", "success"].mean())
    by["gap_closed"] = [gap_closed(x, v, vt) for x in by["success"]]
    by["v_main"], by["vt_aligned"] = v, vt
    # the bound from the generative process, and the ceiling's force rolled out on the held-out
    # episodes (which carries their sampling noise, so it is not the bound)
    by["vision_ceiling"] = oracle.vision_ceiling_success(settings, settings.seed + CEILING_SEED)
    by["vision_ceiling_rollout"] = rolled
    by.insert(
        0, "row_id", [f"H~{h}/E~{e}" for h, e in zip(by["hidden"], by["epochs"], strict=True)]
    )
    return by  # sd is NaN for a cell of one seed: no spread to show
