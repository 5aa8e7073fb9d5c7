"""Cross-sensor transfer (the paper's YCB-Sight row): do alignment heads trained on one tactile
sensor's corpus still make touch add to vision on objects pressed by another sensor?

The target corpus holds several contacts per object (tacgen_lib.corpus.objects) and is split
by object (no object is both fitted and tested). Its label is the object's mass-quantile class
(3 classes: light / medium / heavy). For every *heads* view

- ``none``: the frozen features themselves (V, T), no heads;
- ``source``: both modalities projected by the heads trained on the first sensor's corpus
  (the transfer the paper reports);
- ``target``: the heads retrained on the target corpus's own train objects (the upper
  reference: what alignment gives when it has seen the new sensor);
- ``floor``: the heads trained on the null corpus (touch paired with the wrong object's);

and every probe seed, a logistic probe is fitted on a seeded draw of ``fit_fraction`` of the
train objects (C by object-level stratified CV) for V, for V+T (concatenated) and for V+T with
each object's touch taken from another object (the shuffled control, which a real gain must
beat). Each is scored by balanced accuracy on the fixed test objects; the CI of
Δ = BA(V+T) - BA(V) resamples test OBJECTS (all of an object's contacts together), the same
resamples for every seed, view and arm, so the seeds' mean has a CI too (the mean of each
resample's Δ over seeds).

Every view with heads is evaluated once per alignment seed the heads were trained with
(`evaluate_transfer_seeds`, column ``heads_seed``): the heads' training draw is a replicate of
the transfer, read over its seeds as every replicated difference is (`tacgen_lib.report.claims`
``seeds_interval``), so a conclusion does not rest on one draw of the heads.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tacgen_lib.corpus.derangement import sattolo_cycle
from tacgen_lib.io.schema import SchemaSettings, not_config, schema_fields
from tacgen_lib.probes.bootstrap import resample_counts, resample_indices
from tacgen_lib.probes.folds import make_folds
from tacgen_lib.probes.metrics import balanced_accuracy, balanced_accuracy_resamples

__all__ = [
    "HEADS_VIEWS",
    "TRANSFER_COLUMNS",
    "TransferSettings",
    "TransferSplit",
    "beats_shuffled_control",
    "check_views",
    "evaluate_transfer",
    "evaluate_transfer_seeds",
    "fit_objects",
    "fit_object_probe",
    "shuffled_by_object",
    "views_from_edges",
]

#: the heads views, in report order (module docstring)
HEADS_VIEWS = ("none", "source", "target", "floor")

#: columns of the transfer summary edge (one row per view, heads seed and probe seed, plus a
#: "mean" row per view and heads seed); the frozen features' view has heads seed ""
TRANSFER_COLUMNS = (
    "row_id",
    "heads",
    "heads_from",
    "heads_seed",
    "probe_seed",
    "ba_v",
    "ba_vt",
    "delta",
    "delta_ci_low",
    "delta_ci_high",
    "p_gt0",
    "ba_vt_shuffled",
    "delta_shuffled",
    "delta_shuffled_ci_low",
    "delta_shuffled_ci_high",
    "C_v",
    "C_vt",
    "positive_seeds",
    "n_seeds",
    "n_fit_objects",
    "n_test_objects",
    "n_test_rows",
    "chance",
)


@dataclass(frozen=True)
@schema_fields("transfer", skip=("corpus", "source", "floor"))
class TransferSettings(SchemaSettings):
    """Config ``transfer`` (its corpora are read by the rules): ``classes`` mass-quantile
    classes; ``probe_seeds``; ``fit_fraction`` of the train objects each seed fits on; the
    logistic ``C`` grid and object-level CV ``folds``; ``bootstrap`` object resamples."""

    max_iter: int = not_config(2000)  # the logistic solver's budget and tolerance
    tol: float = not_config(1e-4)


@dataclass(frozen=True)
class TransferSplit:
    """The target corpus's rows: mass class `y`, object index `objects` (0..G-1) and split
    ("train", "val", "test") of each row, all in the row order of the feature matrices."""

    y: np.ndarray
    objects: np.ndarray
    split: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.y)
        if not (len(self.objects) == len(self.split) == n):
            raise ValueError("TransferSplit: y, objects and split need one value per row")
        for name in ("train", "test"):
            if not (self.split == name).any():
                raise ValueError(f"transfer: the target corpus has no {name} objects")
        frame = pd.DataFrame({"o": self.objects, "y": self.y, "s": self.split})
        per_object = frame.groupby("o")[["y", "s"]].nunique()
        if (per_object > 1).any().any():
            bad = int(per_object.index[(per_object > 1).any(axis=1).to_numpy()][0])
            raise ValueError(
                f"transfer: object {bad} has rows of different classes or splits; the rows of "
                "an object must share its class and split (split by object)"
            )
        missing = {int(c) for c in np.unique(self.y)} - {
            int(c) for c in self.y[self.split == "test"]
        }
        if missing:
            raise ValueError(
                f"transfer: mass class(es) {sorted(missing)} have no test object; the test "
                "objects must hold every class"
            )


def fit_objects(
    objects: np.ndarray, object_class: np.ndarray, fraction: float, seed: int
) -> np.ndarray:
    """A seeded draw of ``fraction`` of the given objects, class by class (at least 2 per
    class, or all of a class's objects if it has fewer), sorted: the objects one probe seed
    fits on."""
    objects = np.asarray(objects)
    object_class = np.asarray(object_class)
    rng = np.random.default_rng([int(seed), 0x7472616E])
    keep = []
    for c in np.unique(object_class):
        members = objects[object_class == c]
        k = min(members.size, max(2, int(round(fraction * members.size))))
        keep.append(rng.permutation(members)[:k])
    return np.sort(np.concatenate(keep))


def fit_object_probe(
    X: np.ndarray,
    y: np.ndarray,
    objects: np.ndarray,
    settings: TransferSettings,
    seed: int,
):
    """Standardised logistic probe with C chosen by object-level stratified CV (balanced
    accuracy on the held-out objects' rows; ties to the first C of the grid), refitted on
    every row. Returns (fitted pipeline, chosen C)."""
    from tacgen_lib.probes.logistic import fit_logistic_once

    objects = np.asarray(objects)
    uniq, inverse = np.unique(objects, return_inverse=True)
    object_class = pd.Series(y).groupby(inverse).first().to_numpy()
    k = int(min(settings.folds, np.bincount(pd.factorize(object_class)[0]).min(), uniq.size))
    C = [float(c) for c in settings.C]
    if k < 2 or len(C) == 1:  # nothing to choose between, or too few objects to hold out
        best = C[0]
    else:
        folds = make_folds(uniq.size, k, seed, labels=object_class)
        scores = np.zeros(len(C))
        for held in folds:
            test = np.isin(inverse, held)
            for j, c in enumerate(C):
                fit = fit_logistic_once(
                    X[~test], y[~test], c, settings.max_iter, settings.max_iter, settings.tol
                )
                scores[j] += balanced_accuracy(y[test], fit.model.predict(X[test]))
        best = C[int(np.argmax(scores))]
    final = fit_logistic_once(X, y, best, settings.max_iter, settings.max_iter, settings.tol)
    return final.model, best


def shuffled_by_object(objects: np.ndarray, seed: int) -> np.ndarray:
    """Row indices that give each row the touch of another object: object o's k-th row takes
    the (k mod size)-th row of object sigma(o), sigma a seeded derangement of the objects
    present (`sattolo_cycle`). The pairing-breaking control of the V+T arm."""
    objects = np.asarray(objects)
    uniq = np.unique(objects)
    if uniq.size < 2:
        raise ValueError("shuffled_by_object: need at least 2 objects to pair touch wrongly")
    sigma = sattolo_cycle(uniq.size, np.random.default_rng([int(seed), 0x73687566]))
    rows_of = [np.flatnonzero(objects == o) for o in uniq]
    out = np.empty(objects.size, dtype=np.int64)
    for a, rows in enumerate(rows_of):
        donor = rows_of[sigma[a]]
        out[rows] = donor[np.arange(rows.size) % donor.size]
    return out


def beats_shuffled_control(delta_ci_low: float, delta_shuffled_ci_high: float) -> bool:
    """Whether a summary row's Δ interval lies wholly above the shuffled-touch control's
    (its lower bound above the control's upper bound): the one test the page's sentence and
    the Findings row both apply."""
    return bool(delta_ci_low > delta_shuffled_ci_high)


def _interval(values: np.ndarray) -> tuple[float, float]:
    lo, hi = np.quantile(values, [0.025, 0.975])
    return float(lo), float(hi)


def evaluate_transfer(
    views: Mapping[str, tuple[np.ndarray, np.ndarray]],
    split: TransferSplit,
    settings: TransferSettings,
    heads_from: Mapping[str, str] | None = None,
    progress=None,
    *,
    heads_seed: str = "",
) -> pd.DataFrame:
    """The transfer table (`TRANSFER_COLUMNS`): for every view name -> (V, T) feature
    matrices over the target corpus's rows (module docstring) and every probe seed, balanced
    accuracy of V, V+T and shuffled V+T on the test objects, Δ with its object-bootstrap CI,
    and per view a "mean" row over the seeds (with the count of seeds whose Δ > 0). Every
    row's ``heads_seed`` is `heads_seed` (the alignment seed of the views' heads)."""
    heads_from = dict(heads_from or {})
    y, objects, where = split.y, split.objects, split.split
    uniq, obj_index = np.unique(objects, return_inverse=True)
    train_rows = np.flatnonzero(where == "train")
    test_rows = np.flatnonzero(where == "test")
    train_objects = np.unique(obj_index[train_rows])
    object_class = pd.Series(y).groupby(obj_index).first()
    test_objects, test_group = np.unique(obj_index[test_rows], return_inverse=True)
    idx = resample_indices(test_objects.size, int(settings.bootstrap), int(settings.probe_seeds[0]))
    counts = resample_counts(idx, test_objects.size)
    y_test = y[test_rows]
    n_classes = np.unique(y).size
    rows = []
    for view, (V, T) in views.items():
        V = np.asarray(V, dtype=np.float64)
        T = np.asarray(T, dtype=np.float64)
        VT = np.hstack([V, T])
        per_seed = []
        for seed in settings.probe_seeds:
            fit_objs = fit_objects(
                train_objects,
                object_class.loc[train_objects].to_numpy(),
                settings.fit_fraction,
                seed,
            )
            fit_rows = train_rows[np.isin(obj_index[train_rows], fit_objs)]
            # a row's wrong touch comes from another object of the same split
            within = np.arange(len(y))  # rows neither fitted nor tested keep their own
            for part in (fit_rows, test_rows):
                within[part] = part[shuffled_by_object(obj_index[part], int(seed))]
            VT_shuffled = np.hstack([V, T[within]])
            preds, chosen = {}, {}
            for arm, X in (("v", V), ("vt", VT), ("vt_shuffled", VT_shuffled)):
                model, C = fit_object_probe(
                    X[fit_rows], y[fit_rows], obj_index[fit_rows], settings, int(seed)
                )
                preds[arm], chosen[arm] = model.predict(X[test_rows]), C
            boot = {
                arm: balanced_accuracy_resamples(y_test, p, test_group, counts)
                for arm, p in preds.items()
            }
            ba = {arm: balanced_accuracy(y_test, p) for arm, p in preds.items()}
            per_seed.append((seed, ba, boot, chosen, len(fit_objs)))
            if progress is not None:
                heads = f" (heads seed {heads_seed})" if heads_seed else ""
                progress(
                    f"{view}{heads} seed {seed}: BA V {ba['v']:.3f}, V+T {ba['vt']:.3f}, "
                    f"V+T shuffled {ba['vt_shuffled']:.3f}"
                )
        for seed, ba, boot, chosen, n_fit in per_seed:
            rows.append(
                _row(view, heads_from, str(seed), ba, boot, chosen, n_fit, None, len(per_seed))
            )
        mean_ba = {a: float(np.mean([s[1][a] for s in per_seed])) for a in per_seed[0][1]}
        mean_boot = {a: np.mean([s[2][a] for s in per_seed], axis=0) for a in per_seed[0][2]}
        positive = sum(s[1]["vt"] - s[1]["v"] > 0 for s in per_seed)
        n_fit = int(np.mean([s[4] for s in per_seed]))
        rows.append(
            _row(view, heads_from, "mean", mean_ba, mean_boot, {}, n_fit, positive, len(per_seed))
        )
    out = pd.DataFrame(rows)
    out["n_test_objects"] = int(test_objects.size)
    out["n_test_rows"] = int(test_rows.size)
    out["chance"] = 1.0 / n_classes
    out["heads_seed"] = heads_seed
    out["row_id"] = [
        f"{h}|{heads_seed or '-'}|{s}" for h, s in zip(out["heads"], out["probe_seed"], strict=True)
    ]
    return out[list(TRANSFER_COLUMNS)]


def evaluate_transfer_seeds(
    raw: tuple[np.ndarray, np.ndarray],
    aligned: Mapping[int, Mapping[str, tuple[np.ndarray, np.ndarray]]],
    split: TransferSplit,
    settings: TransferSettings,
    heads_from: Mapping[str, str] | None = None,
    progress=None,
) -> pd.DataFrame:
    """`evaluate_transfer` of the frozen features (`raw`, heads seed "") and, per alignment
    seed -> {view -> (V, T)} in `aligned`, of that seed's views with heads (`views_from_edges`
    order), one table. Every call draws the same object resamples (the first probe seed's),
    so the heads seeds' intervals are over the same test-object draws."""
    if not aligned:
        raise ValueError("evaluate_transfer_seeds: no alignment seed's views given")
    parts = [evaluate_transfer({"none": raw}, split, settings, heads_from, progress)]
    for seed, views in aligned.items():
        headed = {k: v for k, v in views_from_edges(raw, views).items() if k != "none"}
        check_views(headed, len(split.y))
        parts.append(
            evaluate_transfer(headed, split, settings, heads_from, progress, heads_seed=str(seed))
        )
    return pd.concat(parts, ignore_index=True)


def _row(
    view: str,
    heads_from: Mapping[str, str],
    seed: str,
    ba: Mapping[str, float],
    boot: Mapping[str, np.ndarray],
    chosen: Mapping[str, float],
    n_fit: int,
    positive: int | None,
    n_seeds: int,
) -> dict:
    delta = boot["vt"] - boot["v"]
    delta_shuffled = boot["vt_shuffled"] - boot["v"]
    lo, hi = _interval(delta)
    s_lo, s_hi = _interval(delta_shuffled)
    return {
        "heads": view,
        "heads_from": heads_from.get(view, ""),
        "probe_seed": seed,
        "ba_v": ba["v"],
        "ba_vt": ba["vt"],
        "delta": ba["vt"] - ba["v"],
        "delta_ci_low": lo,
        "delta_ci_high": hi,
        "p_gt0": float(np.mean(delta > 0)),
        "ba_vt_shuffled": ba["vt_shuffled"],
        "delta_shuffled": ba["vt_shuffled"] - ba["v"],
        "delta_shuffled_ci_low": s_lo,
        "delta_shuffled_ci_high": s_hi,
        "C_v": float(chosen.get("v", np.nan)),
        "C_vt": float(chosen.get("vt", np.nan)),
        "positive_seeds": -1 if positive is None else int(positive),
        "n_seeds": int(n_seeds),
        "n_fit_objects": int(n_fit),
    }


def views_from_edges(
    raw: tuple[np.ndarray, np.ndarray], aligned: Mapping[str, tuple[np.ndarray, np.ndarray]]
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The views in report order: ``none`` from the raw features, the rest from the aligned
    projections given (those present)."""
    views = {"none": raw}
    for name in HEADS_VIEWS[1:]:
        if name in aligned:
            views[name] = aligned[name]
    return views


def check_views(views: Mapping[str, tuple[np.ndarray, np.ndarray]], n: int) -> None:
    """Every view's V and T hold one finite row per target row."""
    for name, pair in views.items():
        for label, X in zip(("V", "T"), pair, strict=True):
            X = np.asarray(X)
            if X.ndim != 2 or X.shape[0] != n:
                raise ValueError(
                    f"transfer view {name!r}: {label} has shape {X.shape}, want ({n}, d)"
                )
            if not np.isfinite(X).all():
                raise ValueError(f"transfer view {name!r}: {label} has non-finite values")
