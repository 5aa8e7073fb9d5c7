"""One probe family of the paper's protocol: inputs x fusions x controls -> tidy result rows.

This module owns the orchestration of a probe family (``probes.families.<name>`` in config):
which rows train and test the probes, which target is predicted, which V vs V+T comparisons
are made, which controls run on which comparison, and how every outcome becomes one tidy row.
The numerics it calls live in the sibling modules `ridge` and `logistic` (the probes), `fusion`
(V+T variants), `bootstrap` (the fixed-test CI) and `controls` (the controls and the paper's
criterion); file I/O lives in the rule scripts.

Protocol (paper, "Probes")
- Rows: train = the corpus's ``train`` + ``val`` split (the probe has no early stopping, so
  validation rows are ordinary training rows), test = its ``test`` split. For the
  appearance-controlled corpus the split is by object scale (train 0.15/0.20, test 0.25),
  fixed by the split edge. Rows without a label (real corpora) are dropped and counted.
- Target (`target_values`): a manifest column; ``log_mass`` = log(mass); logistic targets
  (``density`` as 3 classes, ``hardness`` soft/hard) are class labels (strings).
- Comparisons (`plan_comparisons`), V vs V+T always on the same rows:
  * ``raw``: V = vision features (pixel or vit), T = tactile ``vit`` features of the heads'
    preprocessing variant; every configured fusion (``concat`` always). A same-dimension
    fusion (mean, max, weighted) runs on raw features only when d_V == d_T and is
    otherwise recorded as a ``skipped`` row with the reason.
  * ``raw`` tactile ablation: T of every other preprocessing variant, ``concat`` with raw V.
  * ``aligned``: V_aligned vs fuse(V_aligned, T_aligned) for every fusion and alignment seed,
    in families whose V is ``vit`` only (`has_aligned_rows`): the heads project ViT features,
    so in a pixel-V family the aligned rows would compare against a ViT-derived V baseline
    unlike its raw rows, and repeat its ViT twin's rows exactly. A pixel-V family compares
    raw pixel V vs V+T; its aligned results live in the ``*_vit`` family of the same target.
- Regulariser: lambda (ridge) or C (logistic) by K-fold CV on the training rows only.
- Statistics per comparison: fixed-test bootstrap (stratified within strata when given),
  percentile 95% CI, p(Delta > 0).
- Controls (budget cap): train-resample diagnostic, tactile-permutation, label-permutation
  and dimension-matched random-feature controls run on the ``concat`` comparison of each input
  (raw with the heads' variant, and aligned per alignment seed) -- the comparisons the paper's
  claims rest on. Logistic controls (about 1,000 lbfgs refits per comparison) run on the raw
  concat and on the first alignment seed's aligned concat only, at lbfgs tol 1e-4
  (`CONTROL_TOL`, `LOGISTIC_CONTROL_ALIGN_SEEDS`). Other comparisons say
  ``controls = "not run"``; their ``delta_ctrl`` and ``criterion_met`` are null, not guessed.
- The paper's criterion (Delta >= 0.03, CI lower bound > 0, Delta_ctrl < Delta, with
  Delta_ctrl the tactile-permutation mean) is a column; nothing is filtered on it.
- Baselines that size a Delta (columns of every row of a family): ``baseline_score``, the
  test score of predicting the training mean (ridge) or the majority training class
  (logistic), `baseline_score`; and ``visible_score``, the test score of the same kind of
  probe on the attributes vision can see, shape and scale (`visible_design`: the best
  shape-only predictor of mass = density x volume(shape, scale) is linear in
  one-hot(shape) x scale^3, of log-mass in one-hot(shape) and log(scale)); NaN where the
  manifest has no shape and scale.

Protocol variants (`protocol_variants.PROTOCOLS`): ``settings.protocol`` picks the probe
`fit_probe` fits -- ``raw`` (the above), ``standardised`` (`scaling`) or ``mlp2`` (`mlp`) --
and every row carries a ``protocol`` column. `run_family` can restrict a variant to the
headline comparisons (``concat`` with the heads' variant, raw and aligned) and leave its
controls out (the default budget); the paper config runs everything under every variant.

Every row carries ``row_id`` = ``family|input|t~variant|fusion|a~align_seed|s~probe_seed|control``
(``...|s~probe_seed|p~protocol|control`` for a protocol other than ``raw``, so raw keys are
those from before the variants existed), unique within a run, the key of the probe edges.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from tacgen_lib.probes.compare import Comparison, compare, confusion_counts
from tacgen_lib.probes.fit import FittedProbe, fit_probe
from tacgen_lib.probes.plan import ComparisonSpec, headline_plan, plan_comparisons, row_id
from tacgen_lib.probes.rows import (
    FamilyRows,
    baseline_score,
    class_order,
    visible_score,
)
from tacgen_lib.probes.settings import ProbeSettings

#: Logistic controls refit ~1,000 lbfgs problems per comparison, so they run on the raw concat
#: comparison and the aligned concat of this many alignment seeds (the first in sorted order);
#: ridge controls are batched solves and run on every concat comparison.
LOGISTIC_CONTROL_ALIGN_SEEDS = 1


# --------------------------------------------------------------------------- a family


@dataclass(frozen=True)
class FamilyResult:
    """Tidy tables of one family and probe seed: results, lambda/C sweep, confusion counts."""

    rows: pd.DataFrame
    sweep: pd.DataFrame
    confusion: pd.DataFrame


@dataclass(frozen=True)
class _Family:
    """What every comparison of one family and probe seed shares: the family's name, rows and
    probe settings, the heads' variant, the constant columns of its result rows (`_family_base`)
    and the class order of its confusion counts (logistic only)."""

    name: str
    rows: FamilyRows
    settings: ProbeSettings
    heads_variant: str
    base: dict
    classes: list


def _family_plan(
    family: str,
    *,
    vision: tuple[np.ndarray, np.ndarray],
    tactile: Mapping[str, tuple[np.ndarray, np.ndarray]],
    aligned: Mapping[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    fusions: Sequence[str],
    heads_variant: str,
    settings: ProbeSettings,
    headline_only: bool,
    controls: bool,
) -> list[ComparisonSpec]:
    """The family's comparisons (`plan_comparisons`), narrowed to the headline ones or stripped
    of their controls where asked (`run_family`)."""
    if heads_variant not in tactile:
        raise ValueError(
            f"family {family!r}: no raw tactile features for the heads' variant {heads_variant!r}"
        )
    plan = plan_comparisons(
        fusions,
        heads_variant=heads_variant,
        variants=list(tactile),
        align_seeds=sorted(aligned),
        dim_v_raw=vision[0].shape[1],
        dim_t_raw=tactile[heads_variant][0].shape[1],
        control_align_seeds=None if settings.kind == "ridge" else LOGISTIC_CONTROL_ALIGN_SEEDS,
    )
    if headline_only:
        plan = headline_plan(plan, heads_variant, controls=controls)
    elif not controls:
        plan = [replace(s, controls=False) for s in plan]
    return plan


def _family_base(
    family: str,
    rows: FamilyRows,
    settings: ProbeSettings,
    heads_variant: str,
    labels: Mapping[str, object] | None,
) -> dict:
    """The columns every result row of the family carries, its baselines included
    (`baseline_score`, `visible_score`)."""
    return {
        "family": family,
        "corpus": rows.corpus,
        "target": rows.target,
        "kind": settings.kind,
        "metric": settings.metric,
        "reg_name": settings.reg_name,
        "probe_seed": settings.seed,
        "protocol": settings.protocol,
        "heads_variant": heads_variant,
        "n_train": rows.n_train,
        "n_test": rows.n_test,
        "n_unlabelled": rows.n_unlabelled,
        "bootstrap_strata": rows.strata_note,
        "baseline_score": baseline_score(rows.y_train, rows.y_test, settings.metric),
        "visible_score": visible_score(rows, settings),
        **(labels or {}),
    }


def _ident(spec: ComparisonSpec) -> dict:
    """The columns that name a comparison in each of the family's tables."""
    return {
        "input": spec.input,
        "t_variant": spec.t_variant,
        "fusion": spec.fusion,
        "align_seed": spec.align_seed,
    }


def _status_row(fam: _Family, key: str, ident: dict, status: str, notes: str) -> dict:
    """The one row of a comparison that gave no result (``skipped`` or ``failed``)."""
    return {
        "row_id": key,
        **fam.base,
        **ident,
        "control": "none",
        "status": status,
        "controls": "not run",
        "notes": notes,
    }


def _compare_spec(
    fam: _Family,
    spec: ComparisonSpec,
    inputs: tuple[tuple, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    v_cache: dict[tuple, FittedProbe],
) -> Comparison:
    """`compare` of one planned comparison on its inputs (cache key, V train, V test, T train,
    T test), the V probe fitted once per input (raw, or an alignment seed) and cached."""
    cache_key, vv_tr, vv_te, tt_tr, tt_te = inputs
    rows, settings = fam.rows, fam.settings
    if cache_key not in v_cache:
        v_cache[cache_key] = fit_probe(
            vv_tr,
            rows.y_train,
            vv_te,
            settings,
            train_ids=rows.train_ids,
            test_ids=rows.test_ids,
        )
    return compare(
        vv_tr,
        vv_te,
        tt_tr,
        tt_te,
        rows,
        spec.fusion,
        settings,
        controls=spec.controls,
        v_probe=v_cache[cache_key],
    )


def _result_rows(
    fam: _Family, spec: ComparisonSpec, key: str, ident: dict, res: Comparison
) -> list[dict]:
    """A comparison's result row and one row per control run on it."""
    settings = fam.settings
    out = [{"row_id": key, **fam.base, **ident, **res.main}]
    for c in res.controls:
        out.append(
            {
                "row_id": row_id(fam.name, spec, settings.seed, c["control"], settings.protocol),
                **fam.base,
                **ident,
                "controls": "run",
                **c,
            }
        )
    return out


def _sweep_rows(fam: _Family, key: str, ident: dict, res: Comparison) -> list[dict]:
    """A comparison's lambda/C sweep, one row per regulariser value (`SWEEP_COLUMNS`)."""
    settings, rows = fam.settings, fam.rows
    return [
        {
            "row_id": f"{key}|{settings.reg_name}={s['reg']:g}",
            "comparison": key,
            "family": fam.name,
            "corpus": rows.corpus,
            "target": rows.target,
            "metric": settings.metric,
            **ident,
            "probe_seed": settings.seed,
            "protocol": settings.protocol,
            "heads_variant": fam.heads_variant,
            "reg_name": settings.reg_name,
            **s,
        }
        for s in res.sweep
    ]


def _confusion_rows(fam: _Family, key: str, ident: dict, res: Comparison) -> list[dict]:
    """A logistic comparison's confusion counts of V and V+T on the test rows
    (`CONFUSION_COLUMNS`)."""
    settings, rows = fam.settings, fam.rows
    return [
        {
            "row_id": f"{key}|{model}|{a}|{b}",
            "comparison": key,
            "family": fam.name,
            "corpus": rows.corpus,
            "target": rows.target,
            **ident,
            "probe_seed": settings.seed,
            "protocol": settings.protocol,
            "heads_variant": fam.heads_variant,
            "model": model,
            "true": a,
            "pred": b,
            "count": n,
        }
        for model, pred in (("V", res.pred_v), ("V+T", res.pred_vt))
        for a, b, n in confusion_counts(rows.y_test, pred, fam.classes)
    ]


def run_family(
    family: str,
    rows: FamilyRows,
    *,
    vision: tuple[np.ndarray, np.ndarray],
    tactile: Mapping[str, tuple[np.ndarray, np.ndarray]],
    aligned: Mapping[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    fusions: Sequence[str],
    heads_variant: str,
    settings: ProbeSettings,
    labels: Mapping[str, object] | None = None,
    progress: Callable[[str], None] | None = None,
    headline_only: bool = False,
    controls: bool,
) -> FamilyResult:
    """Run every planned comparison of one family and probe seed.

    headline_only: only the `headline_plan` comparisons; controls: False leaves every control
    out (the bootstrap CI stays). Both serve the protocol variants' budget.

    vision: raw V features (train rows, test rows), rows in ``rows.train_ids`` /
        ``rows.test_ids`` order; tactile: variant -> raw T features (train, test);
    aligned: alignment seed -> (V_aligned train, V_aligned test, T_aligned train, test).
    labels: constant columns added to every row (e.g. corpus design, vision feature kind).
    A comparison whose probe cannot be fitted (e.g. a class with a single training row) is a
    ``failed`` row with the error as its note; a planned skip is a ``skipped`` row.
    """
    say = progress or (lambda _msg: None)
    plan = _family_plan(
        family,
        vision=vision,
        tactile=tactile,
        aligned=aligned,
        fusions=fusions,
        heads_variant=heads_variant,
        settings=settings,
        headline_only=headline_only,
        controls=controls,
    )
    v_tr, v_te = vision
    fam = _Family(
        name=family,
        rows=rows,
        settings=settings,
        heads_variant=heads_variant,
        base=_family_base(family, rows, settings, heads_variant, labels),
        classes=(class_order([*rows.y_train, *rows.y_test]) if settings.kind == "logistic" else []),
    )
    out_rows, sweep_rows, conf_rows = [], [], []
    v_cache: dict[tuple, FittedProbe] = {}
    for i, spec in enumerate(plan):
        ident = _ident(spec)
        key = row_id(family, spec, settings.seed, protocol=settings.protocol)
        if spec.skip_reason is not None:
            out_rows.append(_status_row(fam, key, ident, "skipped", spec.skip_reason))
            continue
        if spec.input == "raw":
            tt_tr, tt_te = tactile[spec.t_variant]
            inputs = (("raw",), v_tr, v_te, tt_tr, tt_te)
        else:
            vv_tr, vv_te, tt_tr, tt_te = aligned[spec.align_seed]
            inputs = (("aligned", spec.align_seed), vv_tr, vv_te, tt_tr, tt_te)
        try:
            res = _compare_spec(fam, spec, inputs, v_cache)
        except ValueError as exc:
            notes = f"probe could not be fitted: {exc}"
            out_rows.append(_status_row(fam, key, ident, "failed", notes))
            say(f"[{i + 1}/{len(plan)}] {key}: failed ({exc})")
            continue
        out_rows += _result_rows(fam, spec, key, ident, res)
        sweep_rows += _sweep_rows(fam, key, ident, res)
        if settings.kind == "logistic":
            conf_rows += _confusion_rows(fam, key, ident, res)
        say(
            f"[{i + 1}/{len(plan)}] {key}: V {res.main['v_score']:.3f} V+T "
            f"{res.main['vt_score']:.3f} delta {res.main['delta']:+.3f} "
            f"[{res.main['ci_low']:+.3f}, {res.main['ci_high']:+.3f}]"
        )
    return FamilyResult(
        rows=tidy(pd.DataFrame(out_rows)),
        sweep=tidy(_frame(sweep_rows, SWEEP_COLUMNS)),
        confusion=tidy(_frame(conf_rows, CONFUSION_COLUMNS)),
    )


_IDENT = {
    "row_id": "str",
    "comparison": "str",
    "family": "str",
    "corpus": "str",
    "target": "str",
    "input": "str",
    "t_variant": "str",
    "fusion": "str",
    "align_seed": "Int64",
    "probe_seed": "int64",
    "protocol": "str",
    "heads_variant": "str",
}
#: Columns of the lambda/C sweep table (one row per comparison and regulariser value).
SWEEP_COLUMNS = {
    **_IDENT,
    "metric": "str",
    "reg_name": "str",
    "reg": "float64",
    "cv_v": "float64",
    "cv_vt": "float64",
    "test_v": "float64",
    "test_vt": "float64",
    "delta_test": "float64",
    "selected_v": "bool",
    "selected_vt": "bool",
}
#: Columns of the confusion-count table (logistic families; empty for ridge families).
CONFUSION_COLUMNS = {**_IDENT, "model": "str", "true": "str", "pred": "str", "count": "int64"}


def _frame(rows: list[dict], columns: Mapping[str, str]) -> pd.DataFrame:
    """Rows as a frame with exactly `columns`, typed even when there are no rows."""
    frame = pd.DataFrame(rows, columns=list(columns))
    if frame.empty:
        return frame.astype(dict(columns))
    return frame


_INT_COLUMNS = (
    "align_seed",
    "n_iter_v",
    "n_iter_vt",
    "n_resamples",
    "n_constant_resamples",
    "dim_v",
    "dim_vt",
)


def tidy(frame: pd.DataFrame) -> pd.DataFrame:
    """Stable column types for Parquet (and after reading one back): nullable ints for seeds,
    iterations, counts and dimensions; nullable booleans for the criterion and convergence."""
    frame = frame.copy()
    for col in _INT_COLUMNS:
        if col in frame.columns:
            frame[col] = pd.array(
                [None if pd.isna(v) else int(v) for v in frame[col]], dtype="Int64"
            )
    for col in ("criterion_met", "converged"):
        if col in frame.columns:
            frame[col] = pd.array(
                [None if pd.isna(v) else bool(v) for v in frame[col]], dtype="boolean"
            )
    if "notes" in frame.columns:
        frame["notes"] = frame["notes"].fillna("").astype(str)
    return frame
