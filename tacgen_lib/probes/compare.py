"""One V vs V+T comparison: both probes fitted, the fixed-test bootstrap, the controls and the
paper's criterion, the regulariser sweep and the confusion counts."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
from tacgen_lib.probes.controls import (
    PairedRows,
    label_permutation_control,
    paper_criterion,
    random_feature_control,
    tactile_permutation_control,
    train_resample_diagnostic,
)
from tacgen_lib.probes.fit import FittedProbe, fit_probe
from tacgen_lib.probes.fusion import fuse
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.rows import (
    FamilyRows,
)
from tacgen_lib.probes.settings import ProbeSettings

#: The controls, in the order their rows are written.
CONTROLS = ("train_resample", "tactile_permutation", "label_permutation", "random_features")


# --------------------------------------------------------------------------- one comparison


@dataclass
class Comparison:
    """Outcome of one comparison: the main row, control rows, lambda sweep, predictions."""

    main: dict
    controls: list[dict] = field(default_factory=list)
    sweep: list[dict] = field(default_factory=list)
    pred_v: np.ndarray | None = None
    pred_vt: np.ndarray | None = None


def _control_row(name: str, out: dict) -> dict:
    """A control's distribution as a summary row: mean Delta, its 2.5/97.5% quantiles as the
    interval, the share of draws with Delta > 0. V is the V probe's score (mean over refits
    when the control refits it: training resamples, permuted labels)."""
    deltas = np.asarray(out["deltas"], dtype=np.float64)
    v = float(np.mean(out["v_scores"])) if "v_scores" in out else float(out["v_score"])
    n = int(deltas.size)
    return {
        "control": name,
        "status": "ok",
        "v_score": v,
        "vt_score": float(np.mean(out["vt_scores"])),
        "delta": float(out["delta_mean"]),
        "delta_sd": float(out["delta_sd"]),
        "ci_low": float(out["delta_q025"]),
        "ci_high": float(out["delta_q975"]),
        "p_gt0": float(np.mean(deltas > 0.0)),
        "n_resamples": n,
    }


def _main_row(
    boot: dict, v_probe: FittedProbe, vt_probe: FittedProbe, dims: tuple[int, int], controls: bool
) -> dict:
    """The comparison's main row from its fixed-test bootstrap and its two probes (their
    regularisers, convergence and iterations; `dims`: of V and of V+T); the control Delta and
    the criterion are filled in once the controls have run."""
    return {
        "control": "none",
        "status": "ok",
        "v_score": boot["v_score"],
        "vt_score": boot["vt_score"],
        "delta": boot["delta"],
        "delta_sd": math.nan,
        "ci_low": boot["ci_low"],
        "ci_high": boot["ci_high"],
        "p_gt0": boot["p_gt0"],
        "n_resamples": boot["n_resamples"],
        "n_constant_resamples": boot["n_constant_resamples"],
        "v_reg": v_probe.reg,
        "vt_reg": vt_probe.reg,
        "dim_v": int(dims[0]),
        "dim_vt": int(dims[1]),
        "converged": bool(v_probe.converged and vt_probe.converged),
        "n_iter_v": v_probe.n_iter,
        "n_iter_vt": vt_probe.n_iter,
        "controls": "run" if controls else "not run",
        "delta_ctrl": math.nan,
        "criterion_met": None,
        "notes": "",
    }


def _band_columns(bands: pd.DataFrame, pred_v: np.ndarray, pred_vt: np.ndarray) -> dict:
    """The test rows' mean force band (low, high) and the share of V's and V+T's predictions
    inside each row's band."""
    lo, hi = (bands[c].to_numpy() for c in bands.columns)
    return {
        "band_low_mean": float(np.mean(lo)),
        "band_high_mean": float(np.mean(hi)),
        "v_in_band": float(np.mean((pred_v >= lo) & (pred_v <= hi))),
        "vt_in_band": float(np.mean((pred_vt >= lo) & (pred_vt <= hi))),
    }


def _sweep(
    v_probe: FittedProbe, vt_probe: FittedProbe, y_test: np.ndarray, settings: ProbeSettings
) -> list[dict]:
    """One row per regulariser value of the grid: both probes' CV scores, their test R^2 (ridge,
    where the probes kept every lambda's predictions; NaN otherwise) and which value each
    chose."""
    test_v = test_vt = np.full(v_probe.grid.size, np.nan)
    if (
        settings.kind == "ridge"
        and v_probe.pred_grid is not None
        and vt_probe.pred_grid is not None
    ):
        test_v = np.array([score("r2", y_test, p) for p in v_probe.pred_grid])
        test_vt = np.array([score("r2", y_test, p) for p in vt_probe.pred_grid])
    # the mlp2 grid is 2-D (width x weight decay): its choice is in the notes, not the sweep
    return [
        {
            "reg": float(reg),
            "cv_v": float(v_probe.cv_scores[i]),
            "cv_vt": float(vt_probe.cv_scores[i]),
            "test_v": float(test_v[i]),
            "test_vt": float(test_vt[i]),
            "delta_test": float(test_vt[i] - test_v[i]),
            "selected_v": bool(reg == v_probe.reg),
            "selected_vt": bool(reg == vt_probe.reg),
        }
        for i, reg in enumerate(v_probe.grid if settings.protocol != "mlp2" else [])
    ]


def _control_calls(
    v_probe: FittedProbe, vt_probe: FittedProbe, settings: ProbeSettings
) -> list[tuple[str, Callable[..., dict], dict]]:
    """(name, function, keyword arguments) of each control with a positive number of draws, in
    `CONTROLS` order; the probes (at their chosen regularisers) are the V and the V+T probe, or
    the V+T probe that is refitted and the V probe."""
    kind = settings.kind
    fixed_v, fixed_vt = v_probe.fixed(kind), vt_probe.fixed(kind)
    common = {"metric": settings.metric, "seed": settings.draw_seed}
    pair = {"probe_v": fixed_v, "probe_vt": fixed_vt, **common}
    refit = {"probe": fixed_vt, "probe_v": fixed_v, **common}
    runs = {
        "train_resample": (train_resample_diagnostic, pair),
        "tactile_permutation": (tactile_permutation_control, refit),
        "label_permutation": (label_permutation_control, pair),
        "random_features": (random_feature_control, refit),
    }
    draws = {
        "train_resample": ("n_resamples", settings.train_resamples),
        "tactile_permutation": ("n_permutations", settings.permutations),
        "label_permutation": ("n_permutations", settings.label_permutations),
        "random_features": ("n_draws", settings.random_draws),
    }
    return [
        (name, runs[name][0], {**runs[name][1], draws[name][0]: draws[name][1]})
        for name in CONTROLS
        if draws[name][1] > 0
    ]


def _run_control(name: str, control: Callable[..., dict], paired: PairedRows, kwargs: dict) -> dict:
    """One control's row (`_control_row`), or a failed row with the error; the convergence
    warnings of its logistic refits are counted into its notes, other warnings passed on."""
    from sklearn.exceptions import ConvergenceWarning  # only where controls are run

    with warnings.catch_warnings(record=True) as caught:
        # A logistic refit that misses convergence at the iteration cap warns once per
        # refit; the warnings are counted into the control's notes, not flooded to the log.
        warnings.simplefilter("always", category=ConvergenceWarning)
        try:
            row = _control_row(name, control(paired, **kwargs))
        except ValueError as exc:  # e.g. a training resample left holding one class
            row = {"control": name, "status": "failed", "notes": f"control failed: {exc}"}
    for w in caught:
        if not issubclass(w.category, ConvergenceWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    unconverged = sum(issubclass(w.category, ConvergenceWarning) for w in caught)
    if unconverged:
        row["notes"] = f"{unconverged} refit(s) did not converge within the iteration cap"
    return row


def _judge(main: dict, chosen: str, settings: ProbeSettings) -> None:
    """The main row's notes and the paper's criterion once the controls have run: without a
    tactile-permutation Delta, a note and no criterion."""
    main["notes"] = chosen
    if math.isnan(main["delta_ctrl"]):
        main["notes"] = "no tactile-permutation control (probes.permutations = 0, or it failed)"
    else:
        main["criterion_met"] = paper_criterion(
            main["delta"], main["ci_low"], main["delta_ctrl"], settings.min_delta
        )


def compare(
    v_train: np.ndarray,
    v_test: np.ndarray,
    t_train: np.ndarray,
    t_test: np.ndarray,
    rows: FamilyRows,
    fusion: str,
    settings: ProbeSettings,
    *,
    controls: bool,
    v_probe: FittedProbe | None = None,
) -> Comparison:
    """V vs fuse(V, T) on the family's rows: fit, bootstrap, (controls), criterion, sweep.

    v_probe: the V probe fitted on (v_train, y_train), shared between the comparisons of one
    input (it does not depend on T or the fusion). Controls refit at the CV-chosen
    regularisers. Returns the main row (statistics and diagnostics) and, with controls, one
    row per control in `CONTROLS`; seeds are all ``settings.draw_seed``, so every comparison of a
    family sees the same bootstrap resamples and permutations (paired across comparisons).
    """
    y_tr, y_te = rows.y_train, rows.y_test
    x_vt_tr, x_vt_te = fuse(fusion, v_train, t_train), fuse(fusion, v_test, t_test)
    if v_probe is None:
        v_probe = fit_probe(
            v_train, y_tr, v_test, settings, train_ids=rows.train_ids, test_ids=rows.test_ids
        )
    vt_probe = fit_probe(
        x_vt_tr, y_tr, x_vt_te, settings, train_ids=rows.train_ids, test_ids=rows.test_ids
    )
    boot = fixed_test_bootstrap(
        y_te,
        v_probe.pred_test,
        vt_probe.pred_test,
        settings.metric,
        n_resamples=settings.bootstrap,
        seed=settings.draw_seed,
        strata=rows.strata_test,
        sample_ids=rows.test_ids,
    )
    dims = (v_train.shape[1], x_vt_tr.shape[1])
    main = _main_row(boot, v_probe, vt_probe, dims, controls)
    chosen = "; ".join(f"{m}: {p.notes}" for m, p in (("V", v_probe), ("V+T", vt_probe)) if p.notes)
    if rows.bands_test is not None:
        main |= _band_columns(rows.bands_test, v_probe.pred_test, vt_probe.pred_test)
    result = Comparison(main, pred_v=v_probe.pred_test, pred_vt=vt_probe.pred_test)
    result.sweep += _sweep(v_probe, vt_probe, y_te, settings)
    if not controls:
        main["notes"] = "; ".join(
            x
            for x in (
                "controls not run (see the plan: concat comparisons only, and none "
                "under a protocol variant in the default budget)",
                chosen,
            )
            if x
        )
        return result
    calls = _control_calls(v_probe, vt_probe, settings)
    paired = PairedRows(v_train, t_train, y_tr, v_test, t_test, y_te, fusion)
    for name, control, kwargs in calls:
        row = _run_control(name, control, paired, kwargs)
        result.controls.append(row)
        if name == "tactile_permutation" and row.get("status", "ok") == "ok":
            main["delta_ctrl"] = row["delta"]
    _judge(main, chosen, settings)
    return result


def confusion_counts(
    y_true: np.ndarray, y_pred: np.ndarray, classes: Sequence[str]
) -> list[tuple[str, str, int]]:
    """(true, predicted, count) for every pair of classes, zeros included."""
    y_true, y_pred = np.asarray(y_true, dtype=object), np.asarray(y_pred, dtype=object)
    return [(a, b, int(np.sum((y_true == a) & (y_pred == b)))) for a in classes for b in classes]


#: The statistics of a comparison's main row that a summary edge keeps (`Comparison.main`).
MAIN_STATISTICS = ("v_score", "vt_score", "delta", "ci_low", "ci_high", "p_gt0", "n_resamples")


def comparison_frame(rows: Sequence[dict], columns: Sequence[str]) -> pd.DataFrame:
    """Rows of main-row statistics (plus their keys) as a typed edge frame with `columns`:
    the statistics float64 and `n_resamples` nullable Int64 (a failed point has neither),
    `notes` a string."""
    frame = pd.DataFrame(list(rows), columns=list(columns))
    frame["notes"] = frame["notes"].fillna("").astype(str)
    for col in MAIN_STATISTICS[:-1]:
        frame[col] = frame[col].astype(np.float64)
    frame["n_resamples"] = pd.array(
        [None if pd.isna(v) else int(v) for v in frame["n_resamples"]], dtype="Int64"
    )
    return frame
