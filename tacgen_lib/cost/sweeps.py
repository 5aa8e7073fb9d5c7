"""Points of the align, probes, generate and policy knobs (the `points` contract), from each
stage's own outputs and the seconds of the jobs they came from.

Each function takes what a knob's setting produced (ranks, replicate rows, a stage summary)
and the seconds of its jobs (`spread.Seconds`: wall and CPU from the `benchmark:` files, with the
number of files), and returns rows in `points.POINT_COLUMNS` + `direction`:

- `align_points`: top-1 and median rank V→T on the test rows, mean over alignment seeds, with
  a bootstrap CI over the test rows (`spread.retrieval_bootstrap`);
- `bootstrap_spread_points`: the Monte Carlo sd of the probe CI's endpoints across bootstrap
  seeds (chi-square CI: `spread.sd_interval`);
- `permutation_points`: the permutation p-value's resolution 1/(B+1) (exact) and the sd of
  Δ_ctrl across permutation seeds;
- `generate_points`: Δ_gen of one probe target (its fixed-test bootstrap CI, endpoints averaged
  over generator seeds) and the Fréchet distance generated–real (range over seeds);
- `policy_points`: V-only policy success with its bootstrap CI;
- `backbone_points`: per backbone family, V+T − V under the linear probe on each real-corpus
  probe family of config backbones, with its fixed-test bootstrap CI.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from tacgen_lib.cost.points import POINT_COLUMNS
from tacgen_lib.cost.spread import Seconds, retrieval_bootstrap, sd_interval

__all__ = [
    "Seconds",
    "align_points",
    "bootstrap_spread_points",
    "generate_points",
    "backbone_points",
    "permutation_points",
    "point",
    "policy_points",
]


def point(
    knob: str,
    stage: str,
    setting: float,
    label: str,
    is_default: bool,
    metric: str,
    value: float,
    ci: tuple[float, float],
    uncertainty: str,
    seconds: Seconds,
    direction: str = "higher",
) -> dict:
    """One row of the points contract."""
    return dict(
        zip(
            POINT_COLUMNS,
            (
                knob,
                stage,
                float(setting),
                str(label),
                bool(is_default),
                metric,
                float(value),
                float(ci[0]),
                float(ci[1]),
                uncertainty,
                float(seconds.wall),
                float(seconds.cpu),
                int(seconds.n_jobs),
            ),
            strict=True,
        )
    ) | {"direction": direction}


def _setting(label: str) -> float:
    """A knob value as a number for the page ("all" and words keep their order elsewhere)."""
    try:
        return float(label)
    except ValueError:
        return math.nan


def _frame(rows: list[dict]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=[*POINT_COLUMNS, "direction"])


class _Points:
    """The rows of one knob's points, added a setting at a time: `setting` names the setting
    (its x position, label, whether it is the default, its seconds), `add` one metric of it."""

    def __init__(self, knob: str, stage: str, seconds: Mapping[str, Seconds], default: Any):
        self.knob, self.stage, self.seconds, self.default = knob, stage, seconds, default
        self.rows: list[dict] = []
        self._at: tuple[float, str] = (math.nan, "")

    def setting(self, x: float, label: str) -> None:
        self._at = (x, label)

    def add(
        self,
        metric: str,
        value: float,
        ci: tuple[float, float],
        uncertainty: str,
        direction: str = "higher",
    ) -> None:
        x, label = self._at
        self.rows.append(
            point(
                self.knob,
                self.stage,
                x,
                label,
                label == self.default,
                metric,
                value,
                ci,
                uncertainty,
                self.seconds[label],
                direction,
            )
        )

    def frame(self) -> pd.DataFrame:
        return _frame(self.rows)


def align_points(
    knob: str,
    ranks: Mapping[str, Sequence[np.ndarray]],
    seconds: Mapping[str, Seconds],
    default: str,
    *,
    n_resamples: int,
    seed: int,
    n_all: int | None = None,
) -> pd.DataFrame:
    """Points of an alignment knob: per setting label, `ranks` holds one array of V→T ranks
    per alignment seed (the same test rows, same order). `n_all`: the train size that the
    label "all" stands for (the x position of that setting)."""
    out = _Points(knob, "align", seconds, default)
    for label, per_seed in ranks.items():
        r = np.vstack([np.asarray(x) for x in per_seed])
        b = retrieval_bootstrap(r, n_resamples, seed)
        what = f"95 % bootstrap CI over {r.shape[1]} test rows, mean of {r.shape[0]} seed(s)"
        out.setting(n_all if label == "all" and n_all is not None else _setting(label), label)
        out.add("top-1 V→T retrieval (test)", b["top1"], (b["top1_low"], b["top1_high"]), what)
        ci = (b["median_rank_low"], b["median_rank_high"])
        out.add("median rank V→T (test)", b["median_rank"], ci, what, "lower")
    return out.frame()


def bootstrap_spread_points(
    knob: str, reps: pd.DataFrame, seconds: Mapping[str, Seconds], default: str
) -> pd.DataFrame:
    """Points of the bootstrap-resamples knob from replicate rows (columns `label`, `ci_low`,
    `ci_high`: the probe Δ's CI at that B for one bootstrap seed each)."""
    out = _Points(knob, "probes", seconds, default)
    for label, g in reps.groupby("label", sort=False):
        what = f"sd over {len(g)} bootstrap seeds, 95 % chi-square CI"
        out.setting(_setting(label), label)
        for end, col in (("lower", "ci_low"), ("upper", "ci_high")):
            sd, lo, hi = sd_interval(g[col].to_numpy())
            out.add(f"Monte Carlo sd of the CI's {end} end", sd, (lo, hi), what, "lower")
    return out.frame()


def permutation_points(
    knob: str, reps: pd.DataFrame, seconds: Mapping[str, Seconds], default: str
) -> pd.DataFrame:
    """Points of the permutations knob from replicate rows (columns `label`, `n_permutations`,
    `delta_ctrl`: one permutation seed each)."""
    out = _Points(knob, "probes", seconds, default)
    for label, g in reps.groupby("label", sort=False):
        b = int(g["n_permutations"].iloc[0])
        out.setting(float(b), label)
        resolution = "permutation p-value resolution 1/(B+1)"
        out.add(resolution, 1.0 / (b + 1), (math.nan, math.nan), "exact", "lower")
        sd, lo, hi = sd_interval(g["delta_ctrl"].to_numpy())
        what = f"sd over {len(g)} permutation seeds, 95 % chi-square CI"
        out.add("Monte Carlo sd of Δ_ctrl", sd, (lo, hi), what, "lower")
    return out.frame()


def generate_points(
    knob: str,
    cells: pd.DataFrame,
    seconds: Mapping[str, Seconds],
    default: str,
    *,
    target: str,
) -> pd.DataFrame:
    """Points of a generator knob. cells: the t_gen rows of the generation summary for one
    corpus and target, with a `label` column naming the knob setting (and `setting`), one row
    per generator seed."""
    out = _Points(knob, "generate", seconds, default)
    for label, g in cells.groupby("label", sort=False):
        n = len(g)
        out.setting(float(g["setting"].iloc[0]), label)
        d = float(g["delta"].mean())
        lo, hi = float(g["ci_low"].mean()), float(g["ci_high"].mean())
        what = f"95 % fixed-test bootstrap CI, endpoints averaged over {n} generator seed(s)"
        out.add(f"Δ_gen ({target}, test)", d, (min(lo, d), max(hi, d)), what)
        fd = g["frechet"].to_numpy(dtype=np.float64)
        ci = (float(fd.min()), float(fd.max()))
        what = f"range over {n} generator seed(s)"
        out.add("Fréchet distance generated–real (test)", float(fd.mean()), ci, what, "lower")
    return out.frame()


def policy_points(
    knob: str, cells: pd.DataFrame, seconds: Mapping[str, Seconds], default: str
) -> pd.DataFrame:
    """Points of a policy knob. cells: V-only rows of the policy summary with `label`,
    `setting`, success and its CI, one row per policy seed."""
    out = _Points(knob, "policy", seconds, default)
    for label, g in cells.groupby("label", sort=False):
        out.setting(float(g["setting"].iloc[0]), label)
        s = float(g["success"].mean())
        lo, hi = float(g["ci_low"].mean()), float(g["ci_high"].mean())
        what = (
            f"95 % bootstrap CI over {int(g['n_episodes'].iloc[0])} episodes, "
            f"mean of {len(g)} seed(s)"
        )
        out.add("V-only success rate (held-out episodes)", s, (min(lo, s), max(hi, s)), what)
    return out.frame()


def backbone_points(
    knob: str,
    rows: pd.DataFrame,
    seconds: Mapping[str, Seconds],
    order: Sequence[str],
    default: str | None,
) -> pd.DataFrame:
    """Points of the backbone-family knob. rows: the backbone families' summary (rule
    aggregate_backbones); one point per family in `order` (its position is the setting;
    `default`, the main DAG's family, is the run's own) and real-corpus probe family, under
    the linear probe. seconds: per family, what making its backbones and the probe corpora's
    features cost."""
    out = _Points(knob, "features", seconds, default)
    linear = rows[(rows["protocol"] == "raw") & ~rows["null_corpus"] & (rows["status"] == "ok")]
    for i, family in enumerate(order):
        out.setting(float(i), family)
        for r in linear[linear["family"] == family].itertuples():
            ci = (min(r.ci_low, r.delta), max(r.ci_high, r.delta))
            metric = f"{r.probe}: Δ{r.metric} V+T − V (linear, test)"
            out.add(metric, r.delta, ci, "95 % fixed-test bootstrap CI")
    return out.frame()
