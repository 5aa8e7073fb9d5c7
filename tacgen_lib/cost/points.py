"""The knob-sweep contract: one table per knob, one row per (setting, metric).

Every sweep rule (rules/cost*.smk) writes `results/cost/points/{knob}.parquet` with exactly
`POINT_COLUMNS`, one row per setting of the knob and metric it reports:

- `knob`: the knob's name in config/cost.yaml; `stage`: corpus | features | align | probes |
  generate | policy;
- `setting`: the knob's value as a number (for the log x-axis of the page; categorical knobs
  such as a sampler use their position), `label`: that value as the user writes it;
- `is_default`: the embedded default's setting of this knob;
- `metric`: what the setting buys, named with its unit ("force probe R² (test)", "Δ accuracy
  pretrained − random"), `value` its point estimate, `ci_low`/`ci_high` its uncertainty (a 95 %
  bootstrap CI, or mean ± t·sd over seeds; `uncertainty` says which);
- `wall_s`, `cpu_s`: the seconds the setting costs, summed over the `benchmark:` files of the
  jobs it needs (`n_jobs` of them), never read from inside an edge. Where a setting is run
  several times only to measure its uncertainty (replicate seeds of one job), the seconds are
  the mean over those replicate jobs (the cost of one run at that setting) and `n_jobs`
  counts the benchmark files read.

One optional column, `direction` ("higher" | "lower": which way the metric improves; "higher"
when absent), tells the page which way the Pareto front and the sentences read.
"""

from __future__ import annotations

import pandas as pd

__all__ = [
    "DIRECTIONS",
    "POINT_COLUMNS",
    "check_points",
    "log_points",
    "read_points",
    "write_points",
]

POINT_COLUMNS = [
    "knob",
    "stage",
    "setting",
    "label",
    "is_default",
    "metric",
    "value",
    "ci_low",
    "ci_high",
    "uncertainty",
    "wall_s",
    "cpu_s",
    "n_jobs",
]


#: Which way a metric improves: the optional `direction` column's values.
DIRECTIONS = ("higher", "lower")


def check_points(table: pd.DataFrame, source: str) -> pd.DataFrame:
    """The table in `POINT_COLUMNS` order plus `direction` ("higher" where absent); a missing
    column, a non-finite time, an unknown direction or a CI that does not bracket its value
    raises, naming `source` and the knob's setting."""
    missing = [c for c in POINT_COLUMNS if c not in table.columns]
    if missing:
        raise ValueError(f"{source}: cost points lack columns {missing}")
    direction = table["direction"] if "direction" in table.columns else "higher"
    table = table[POINT_COLUMNS].assign(direction=direction).reset_index(drop=True)
    bad = sorted(set(table["direction"]) - set(DIRECTIONS))
    if bad:
        raise ValueError(f"{source}: cost points direction {bad} is not one of {DIRECTIONS}")
    for r in table.itertuples(index=False):
        where = f"{source}: knob {r.knob!r} setting {r.label!r} metric {r.metric!r}"
        if not (pd.notna(r.wall_s) and r.wall_s >= 0):
            raise ValueError(f"{where}: wall seconds {r.wall_s!r} is not a finite time")
        if pd.notna(r.ci_low) and not (r.ci_low <= r.value <= r.ci_high):
            raise ValueError(f"{where}: value {r.value} outside [{r.ci_low}, {r.ci_high}]")
    return table


def write_points(table: pd.DataFrame, path: str, source: str) -> pd.DataFrame:
    """Check `table` (`check_points`) and write it to `path` as Parquet, atomically. Not an
    edge (no sidecar): its seconds vary from run to run (docs/layout.md, Edges)."""
    import io

    from tacgen_lib.io.hashed import atomic_write_bytes

    table = check_points(table, source)
    sink = io.BytesIO()
    table.to_parquet(sink, index=False)
    atomic_write_bytes(path, sink.getvalue())
    return table


def read_points(path: str) -> pd.DataFrame:
    """A knob's points, checked (`check_points`, naming `path` on a bad table)."""
    return check_points(pd.read_parquet(path), str(path))


def log_points(table: pd.DataFrame, say) -> None:
    """One log line per point: the knob's setting, the metric with its uncertainty, the
    seconds (`say`: the rule's logger's `info`)."""
    for r in table.itertuples(index=False):
        say(
            "%s = %s: %s %.4g [%.4g, %.4g] in %.1f s wall, %.1f s CPU (%d jobs)",
            r.knob,
            r.label,
            r.metric,
            r.value,
            r.ci_low,
            r.ci_high,
            r.wall_s,
            r.cpu_s,
            r.n_jobs,
        )
