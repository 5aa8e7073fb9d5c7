"""What a swept knob's settings bought: the main rules' edges of each setting, read into the
knob's cost points (`tacgen_lib.cost.points`).

Every setting of a swept knob (`tacgen_lib.cost.knobs`) ran main rules under its own folder;
rule `cost_knob_points` hands each reader the settings (`SettingRun`: label, x position,
default flag, replicate, the setting's edges by role, its benchmark files) and the reader
returns the knob's points. `KNOBS[knob].reads` names the reader; `READERS` is the lookup.

- `align`: the probes' heads cell of `train_heads` (its `ranks` edge per alignment seed):
  top-1 and median rank V→T with a bootstrap CI over the test rows;
- `probe_bootstrap`, `probe_permutations`: the headline row (raw, concat, the heads' variant)
  of `probe` per replicate resample seed: the Monte Carlo spread of the CI ends / of Δ_ctrl;
- `features`: the `pretrained_vs_random` table: each modality's accuracy of the backbone in
  use, and Δ pretrained − random;
- `simulation`: the reduced corpus's force band width, the headline Δ of its probe families
  and the simulate job's frames per second.

The free knobs' settings are a stage's own grid (no rerun): each run is one cell of it (one
per seed where the stage has seeds), its `summary` the stage's summary table:

- `generate`: Δ_gen and the Fréchet distance of the generation summary's t_gen rows of one
  corpus, target and guidance, per (sampler, steps) cell (`options`: sampler, steps);
- `policy`: the V-only success of the policy summary per (hidden, epochs) cell;
- `backbones`: each backbone family's V+T − V on the families' summary.

A setting's seconds are assembled in one place, `spread.setting_seconds`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from tacgen_lib.cost import sweeps
from tacgen_lib.cost.knob_metrics import (
    BAND_WIDTH,
    FRAMES_PER_S,
    PERCENTILE_CI,
    KnobSetting,
    features_metrics,
    force_band_width,
    knob_points,
    metric_row,
    probe_metric_ids,
)
from tacgen_lib.cost.spread import Seconds, setting_seconds
from tacgen_lib.runtime.benchmarks import Benchmark

__all__ = ["EDGE_COLUMNS", "READERS", "SettingRun", "headline_row", "read_knob"]

#: the columns a reader uses of each edge role (the key is always read; a role not named here
#: is read whole): a reduced corpus's samples edge also holds every frame as PNG bytes
EDGE_COLUMNS: dict[str, tuple[str, ...]] = {
    "samples": ("force_p05", "force_p95"),
    "ranks": ("rank_v2t",),
    "metrics": ("n_train_rows",),
}


@dataclass(frozen=True)
class SettingRun:
    """One run of a setting as the reader sees it. `edges`: role -> list of frames (one per
    alignment seed, probe family...), already read; `benchmarks`: its jobs' benchmark files,
    read; `options`: what the reader needs from the setting's config (resamples, whether the
    backbone was pretrained, the reduced corpus's size)."""

    label: str
    number: float
    is_default: bool
    rep: int
    edges: Mapping[str, Sequence[pd.DataFrame]]
    benchmarks: Sequence[Benchmark]
    options: Mapping[str, Any] = field(default_factory=dict)


def _seconds(runs: Sequence[SettingRun]) -> dict[str, Seconds]:
    """Per label: the cost of one run (`setting_seconds`; replicates of a setting averaged)."""
    by_label: dict[str, list[Sequence[Benchmark]]] = {}
    for r in runs:
        by_label.setdefault(r.label, []).append(r.benchmarks)
    return {label: setting_seconds(reps) for label, reps in by_label.items()}


def _default_label(runs: Sequence[SettingRun]) -> str | None:
    return next((r.label for r in runs if r.is_default), None)


def headline_row(rows: pd.DataFrame, control: str = "none") -> pd.Series:
    """The probe job's headline comparison: raw features, concat fusion, the heads' tactile
    variant (each row's `heads_variant`), and `control` ("none": the comparison itself).
    Raises naming what is missing."""
    hit = rows[
        (rows["input"] == "raw")
        & (rows["fusion"] == "concat")
        & (rows["t_variant"] == rows["heads_variant"])
        & (rows["control"] == control)
    ]
    if len(hit) != 1:
        raise ValueError(
            f"probe rows of {sorted(set(rows['family']))}: {len(hit)} headline rows "
            f"(raw, concat, the heads' variant, control {control}); expected 1"
        )
    return hit.iloc[0]


def read_align(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]) -> pd.DataFrame:
    ranks = {r.label: [f["rank_v2t"].to_numpy() for f in r.edges["ranks"]] for r in runs}
    n_all = next(
        (int(r.edges["metrics"][0]["n_train_rows"].iloc[0]) for r in runs if r.label == "all"),
        None,
    )
    return sweeps.align_points(
        knob,
        ranks,
        _seconds(runs),
        _default_label(runs),
        n_resamples=int(options["bootstrap"]),
        seed=0,
        n_all=n_all,
    )


def _replicates(runs: Sequence[SettingRun]) -> pd.DataFrame:
    out = []
    for r in runs:
        rows = r.edges["rows"][0]
        main = headline_row(rows)
        perm = headline_row(rows, "tactile_permutation")
        out.append(
            {
                "label": r.label,
                "rep": r.rep,
                "delta": main["delta"],
                "ci_low": main["ci_low"],
                "ci_high": main["ci_high"],
                "n_permutations": int(perm["n_resamples"]),
                "delta_ctrl": perm["delta"],
                "delta_ctrl_sd": perm["delta_sd"],
            }
        )
    return pd.DataFrame(out)


def read_probe_bootstrap(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]):
    reps = _replicates(runs)
    return sweeps.bootstrap_spread_points(knob, reps, _seconds(runs), _default_label(runs))


def read_probe_permutations(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]):
    reps = _replicates(runs)
    return sweeps.permutation_points(knob, reps, _seconds(runs), _default_label(runs))


def _settings(runs: Sequence[SettingRun], metrics: Callable[[SettingRun], list[dict]]):
    return [
        KnobSetting(r.number, r.label, r.is_default, pd.DataFrame(metrics(r)), r.benchmarks)
        for r in runs
    ]


def read_features(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]):
    def metrics(r: SettingRun) -> list[dict]:
        return features_metrics(
            r.edges["table"][0],
            pretraining=bool(r.options["pretraining"]),
            n_resamples=int(options["bootstrap"]),
        )

    return knob_points(knob, "features", _settings(runs, metrics), options["metrics"])


def read_simulation(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]):
    b, seed = int(options["bootstrap"]), int(options["seed"])

    def metrics(r: SettingRun) -> list[dict]:
        samples = r.edges["samples"][0]
        width, lo, hi = force_band_width(
            samples["force_p05"].to_numpy(),
            samples["force_p95"].to_numpy(),
            n_resamples=b,
            seed=seed,
        )
        out = [
            metric_row(
                BAND_WIDTH, width, lo, hi, f"95 % bootstrap CI over the {len(samples)} samples"
            )
        ]
        for rows in r.edges["rows"]:
            h = headline_row(rows)
            out.append(
                metric_row(
                    probe_metric_ids(h["target"], h["metric"])[1],
                    h["delta"],
                    h["ci_low"],
                    h["ci_high"],
                    PERCENTILE_CI.format(b=int(h["n_resamples"])),
                )
            )
        simulate = r.benchmarks[0]  # the simulate job comes first
        out.append(
            metric_row(
                FRAMES_PER_S,
                len(samples) / simulate.wall,
                math.nan,
                math.nan,
                "none: one job's wall time (benchmark file)",
            )
        )
        return out

    return knob_points(knob, "corpus", _settings(runs, metrics), options["metrics"])


def _cells(rows: pd.DataFrame, keys: list[tuple], cells: Mapping[tuple, SettingRun]):
    """`rows` of the grid cells the runs name (`keys`: each row's cell), with each run's
    `label` and x position (`setting`)."""
    keep = [k in cells for k in keys]
    kept = [k for k in keys if k in cells]
    return rows[keep].assign(
        label=[cells[k].label for k in kept], setting=[cells[k].number for k in kept]
    )


def read_generate(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]):
    summary = runs[0].edges["summary"][0]
    cells = {(r.options["sampler"], int(r.options["steps"])): r for r in runs}
    rows = summary[
        (summary["input"] == "t_gen")
        & (summary["corpus"] == options["corpus"])
        & (summary["target"] == options["target"])
        & (summary["guidance"].astype(float) == float(options["guidance"]))
    ]
    keys = [(s, int(st)) for s, st in zip(rows["sampler"], rows["steps"], strict=True)]
    rows = _cells(rows, keys, cells)
    if rows.empty:
        raise ValueError(
            f"knob {knob!r}: the generation summary has no t_gen rows for corpus "
            f"{options['corpus']!r}, target {options['target']!r}, guidance {options['guidance']}"
        )
    seconds, default = _seconds(runs), _default_label(runs)
    return sweeps.generate_points(knob, rows, seconds, default, target=options["target"])


def read_policy(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]):
    summary = runs[0].edges["summary"][0]
    cells = {(int(r.options["hidden"]), int(r.options["epochs"])): r for r in runs}
    rows = summary[summary["condition"] == "v"]
    keys = [(int(h), int(e)) for h, e in zip(rows["hidden"], rows["epochs"], strict=True)]
    return sweeps.policy_points(
        knob, _cells(rows, keys, cells), _seconds(runs), _default_label(runs)
    )


def read_backbones(knob: str, runs: Sequence[SettingRun], options: Mapping[str, Any]):
    rows, order = runs[0].edges["summary"][0], [r.label for r in runs]
    return sweeps.backbone_points(knob, rows, _seconds(runs), order, _default_label(runs))


READERS: dict[str, Callable[[str, Sequence[SettingRun], Mapping[str, Any]], pd.DataFrame]] = {
    "align": read_align,
    "probe_bootstrap": read_probe_bootstrap,
    "probe_permutations": read_probe_permutations,
    "features": read_features,
    "simulation": read_simulation,
    "generate": read_generate,
    "policy": read_policy,
    "backbones": read_backbones,
}


def read_knob(
    knob: str, reader: str, runs: Sequence[SettingRun], options: Mapping[str, Any]
) -> pd.DataFrame:
    """The knob's points from its settings' runs (`READERS[reader]`)."""
    if not runs:
        raise ValueError(f"knob {knob!r}: no settings")
    if reader not in READERS:
        raise ValueError(f"knob {knob!r}: no reader {reader!r} (have {sorted(READERS)})")
    return READERS[reader](knob, runs, options)
