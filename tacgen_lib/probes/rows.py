"""The rows and target of one probe family: which samples train and test it, what it
predicts, its bootstrap strata and uncertainty bands, and the baselines that size its Δ
(predicting the training mean or majority class; the same probe on what vision can see)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io import edges
from tacgen_lib.probes.metrics import score
from tacgen_lib.probes.settings import ProbeFamily, ProbeSettings
from tacgen_lib.probes.subsets import within_scale_split

#: Targets whose uncertainty bands travel with the results: target -> (low, high) columns.
BANDS = {"force_p50": ("force_p05", "force_p95")}
#: The columns whose product defines the bootstrap strata of a controlled corpus.
CONTROLLED_STRATA = ("shape", "density", "scale")


# --------------------------------------------------------------------------- rows + target


def target_values(frame: pd.DataFrame, target: str, kind: str) -> np.ndarray:
    """The probe target of each row: float for ridge, class labels (str) for logistic.

    ``log_mass`` is log(mass) (mass must be > 0). Missing labels come back as NaN (ridge) or
    None (logistic); `family_rows` drops those rows. A logistic class label is the value as
    text (``density`` 600.0 -> "600.0"), so numbers and words are treated alike.
    """
    source = "mass" if target == "log_mass" else target
    if source not in frame.columns:
        raise ValueError(
            f"target {target!r}: the manifest has no column {source!r} "
            f"(columns: {', '.join(sorted(map(str, frame.columns)))})"
        )
    col = frame[source]
    if kind == "ridge":
        values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64)
        if target == "log_mass":
            bad = values <= 0
            if bad.any():
                sid = frame["sample_id"].iloc[int(np.flatnonzero(bad)[0])]
                raise ValueError(f"target log_mass: sample_id {sid!r} has mass <= 0")
            values = np.log(values)
        return values
    labels = np.empty(len(col), dtype=object)
    for i, v in enumerate(col.tolist()):
        missing = v is None or (isinstance(v, float) and math.isnan(v))
        labels[i] = None if missing else str(v)
    return labels


@dataclass(frozen=True)
class FamilyRows:
    """The labelled train and test rows of one family, in sample_id order."""

    corpus: str
    target: str
    kind: str
    train_ids: np.ndarray
    test_ids: np.ndarray
    y_train: np.ndarray
    y_test: np.ndarray
    strata_test: np.ndarray | None  # bootstrap strata of the test rows (or None)
    bands_test: pd.DataFrame | None  # (low, high) band columns of the test rows (or None)
    n_unlabelled: int  # rows of the corpus dropped for a missing label
    strata_note: str = "none"  # how the bootstrap strata were formed (a summary column)
    visible_train: np.ndarray | None = None  # `visible_design` of the train rows (or None)
    visible_test: np.ndarray | None = None

    @property
    def n_train(self) -> int:
        return int(self.train_ids.size)

    @property
    def n_test(self) -> int:
        return int(self.test_ids.size)

    def read_block(self, path: str, column: str) -> tuple[np.ndarray, np.ndarray]:
        """`train_test` of vector column `column` of the edge at `path` (read and verified)."""
        return self.train_test(edges.read(path, require={column: "vector"}), column)

    def train_test(self, edge, column: str) -> tuple[np.ndarray, np.ndarray]:
        """(train, test) arrays of one vector column of a verified edge
        (`tacgen_lib.io.edges.Edge`), rows in this family's sample_id order."""
        return (
            edge.subset(self.train_ids).vectors[column],
            edge.subset(self.test_ids).vectors[column],
        )


def strata_for(corpus: Mapping) -> tuple[str, ...] | None:
    """The bootstrap strata of a corpus's test rows (its config entry): the appearance-
    controlled design resamples within `CONTROLLED_STRATA`; any other corpus unstratified."""
    return CONTROLLED_STRATA if corpus.get("design") == "controlled" else None


def pool_strata(labels: np.ndarray, min_size: int = 2) -> tuple[np.ndarray, int]:
    """Bootstrap strata with at least `min_size` rows each: smaller cells are pooled.

    Resampling within a one-row cell always returns that row, which would shrink the CI for
    no reason; such rows are pooled into one stratum "pooled" (and if that pool is itself
    too small, the smallest remaining cells join it until it is not). Returns the labels and
    the number of pooled rows.
    """
    labels = np.asarray(labels, dtype=object).copy()
    counts = pd.Series(labels).value_counts()
    small = set(counts.index[counts < min_size])
    pooled = np.isin(labels, list(small))
    rest = counts[counts >= min_size].sort_values(kind="stable")
    for cell in rest.index:
        if pooled.sum() == 0 or pooled.sum() >= min_size:
            break
        pooled |= labels == cell
    labels[pooled] = "pooled"
    return labels, int(pooled.sum())


def family_rows(
    manifest: pd.DataFrame,
    splits: pd.DataFrame,
    *,
    corpus: str,
    target: str,
    kind: str,
    strata: Sequence[str] | None = None,
    within_scale: tuple[float, int] | None = None,
) -> FamilyRows:
    """Train (train + val) and test rows of `corpus` with their targets (sorted by sample_id).

    strata: manifest columns whose joint value defines bootstrap strata of the test rows
    (e.g. `CONTROLLED_STRATA`); None for unstratified resampling.
    within_scale: (test_fraction, seed) for the held-out-scale diagnosis: the train + val rows
    ONLY are re-split at random within each object scale (`subsets.within_scale_split`); the
    corpus's test rows are left out entirely (they never train anything).
    """
    rows = manifest.loc[manifest["corpus"] == corpus]
    if rows.empty:
        raise ValueError(f"corpus {corpus!r}: no rows in the manifest")
    rows = rows.merge(splits[["sample_id", "split"]], on="sample_id", how="left", validate="1:1")
    unsplit = rows["split"].isna()
    if unsplit.any():
        raise ValueError(
            f"corpus {corpus!r}: sample_id {rows.loc[unsplit, 'sample_id'].iloc[0]!r} "
            "is not in the split edge; rebuild the splits"
        )
    rows = rows.sort_values("sample_id", ignore_index=True)
    y = target_values(rows, target, kind)
    labelled = np.array([v is not None and v == v for v in y], dtype=bool)
    rows, y = rows.loc[labelled].reset_index(drop=True), y[labelled]
    train = rows["split"].isin(["train", "val"]).to_numpy()
    test = (rows["split"] == "test").to_numpy()
    if within_scale is not None:
        if "scale" not in rows.columns:
            raise ValueError(f"corpus {corpus!r}: within-scale split needs a 'scale' column")
        pool = np.flatnonzero(train)
        tr_i, te_i = within_scale_split(rows["scale"].to_numpy()[pool], *within_scale)
        train, test = np.zeros(len(rows), bool), np.zeros(len(rows), bool)
        train[pool[tr_i]], test[pool[te_i]] = True, True
    if not train.any() or not test.any():
        raise ValueError(
            f"corpus {corpus!r}, target {target!r}: {int(train.sum())} labelled train/val and "
            f"{int(test.sum())} labelled test rows; a probe needs both"
        )
    strata_test, strata_note = None, "none"
    if strata:
        missing = [c for c in strata if c not in rows.columns]
        if missing:
            raise ValueError(f"corpus {corpus!r}: no strata column(s) {missing} in the manifest")
        cells = rows.loc[test, list(strata)].astype(str).agg(" x ".join, axis=1)
        strata_test, n_pooled = pool_strata(cells.to_numpy(dtype=object))
        strata_note = f"{' x '.join(strata)}: {len(set(strata_test))} strata" + (
            f" ({n_pooled} test rows of cells with < 2 rows pooled)" if n_pooled else ""
        )
    bands_test = None
    if target in BANDS and all(c in rows.columns for c in BANDS[target]):
        bands_test = rows.loc[test, list(BANDS[target])].reset_index(drop=True).astype(float)
    ids = rows["sample_id"].to_numpy(dtype=object)
    visible = (None, None)
    if all(c in rows.columns for c in VISIBLE) and rows[list(VISIBLE)].notna().all().all():
        visible = visible_design(
            rows.loc[train], rows.loc[test], log_target=target.startswith("log_")
        )
    return FamilyRows(
        corpus=corpus,
        target=target,
        kind=kind,
        train_ids=ids[train],
        test_ids=ids[test],
        y_train=y[train],
        y_test=y[test],
        strata_test=strata_test,
        strata_note=strata_note,
        bands_test=bands_test,
        n_unlabelled=int((~labelled).sum()),
        visible_train=visible[0],
        visible_test=visible[1],
    )


#: Manifest columns of what vision can see of an object (the appearance-controlled design).
VISIBLE = ("shape", "scale")


def trainable_family_rows(
    manifest: pd.DataFrame,
    splits: pd.DataFrame,
    family: ProbeFamily,
    corpus: Mapping,
    *,
    rule: str,
    within_scale: tuple[float, int] | None = None,
) -> FamilyRows:
    """`family_rows` of `family` on its corpus (declaration `corpus`: the bootstrap's strata),
    refusing any test row among the rows its probes train on (`assert_trainable`, naming
    `rule`): they train on train + val rows, test rows only score them."""
    rows = family_rows(
        manifest,
        splits,
        corpus=family.corpus,
        target=family.target,
        kind=family.kind,
        strata=strata_for(corpus),
        within_scale=within_scale,
    )
    assert_trainable(rows.train_ids, splits, rule=rule, allowed=("train", "val"))
    return rows


def visible_design(
    train: pd.DataFrame, test: pd.DataFrame, *, log_target: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Design of the visible attributes shape and scale, for the shape-only ceiling.

    The best shape-only predictor of mass = density x c_shape x scale^3 (density unseen) is
    E[density] c_shape scale^3, linear in one-hot(shape) x scale^3; of log-mass
    (``log_target``) it is E[log density] + log c_shape + 3 log scale, linear in one-hot(shape)
    and log(scale). One form per target: the controlled split holds two training scales, on
    which scale^3 and log(scale) are collinear within a shape, so a design holding both would
    extrapolate to the test scale by an arbitrary mix of them. Columns are standardised with
    the TRAINING rows' mean and SD (a constant column is centred only); shapes are the union of
    both row sets' (a shape seen only in test has an all-zero training column).
    """
    shapes = sorted(set(train["shape"].astype(str)) | set(test["shape"].astype(str)))

    def design(frame: pd.DataFrame) -> np.ndarray:
        onehot = (frame["shape"].astype(str).to_numpy()[:, None] == np.array(shapes)).astype(float)
        scale = frame["scale"].to_numpy(dtype=np.float64)
        if log_target:
            return np.column_stack([onehot, np.log(scale)])
        return onehot * scale[:, None] ** 3

    x_tr, x_te = design(train), design(test)
    mu, sd = x_tr.mean(axis=0), x_tr.std(axis=0)
    sd = np.where(sd > 0, sd, 1.0)
    return (x_tr - mu) / sd, (x_te - mu) / sd


def baseline_score(y_train: np.ndarray, y_test: np.ndarray, metric: str) -> float:
    """Test score of the constant predictor fitted on the training rows: their mean (R^2) or
    their majority class (accuracy; ties to the first class in `class_order`)."""
    if metric == "r2":
        mean = float(np.mean(np.asarray(y_train, dtype=np.float64)))
        return score("r2", y_test, np.full(len(y_test), mean))
    labels = np.asarray(y_train, dtype=object)
    classes = class_order(labels)
    counts = [int(np.sum(labels == c)) for c in classes]
    majority = classes[int(np.argmax(counts))]
    return score("accuracy", np.asarray(y_test, dtype=object), np.full(len(y_test), majority))


def visible_score(rows: FamilyRows, settings: ProbeSettings) -> float:
    """Test score of the family's probe kind (regulariser by CV on the training rows) on the
    visible attributes (`visible_design`): the best a shape-only predictor attains, NaN when
    the manifest has no shape and scale."""
    if rows.visible_train is None:
        return math.nan
    from tacgen_lib.probes.fit import fit_probe  # here: most users of the rows fit no probe

    try:
        fit = fit_probe(rows.visible_train, rows.y_train, rows.visible_test, settings)
    except ValueError:  # e.g. a class with one training row: no CV, no ceiling
        return math.nan
    return score(settings.metric, rows.y_test, fit.pred_test)


def class_order(labels: Sequence) -> list[str]:
    """Distinct class labels in natural order: numerically when every label is a number
    ("500.0" < "2000.0"), else alphabetically."""
    distinct = sorted({str(x) for x in labels})
    try:
        return sorted(distinct, key=float)
    except ValueError:
        return distinct
