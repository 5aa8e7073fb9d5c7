"""Fixed splits and the split guard (docs/layout.md, Corpus edges).

Splits are made once, from the fused manifest, before any feature is computed, and stored as an
edge (`sample_id`, `corpus`, `split`). Two policies:

- `stratified`: per corpus, a stratified random split at a fixed seed (42 in the paper) over the
  `stratum` column (for SSVTP-style data the top-5 adjective patterns; for the simulated paired
  corpus shape | hardness | density). Strata too small to stratify are pooled into "rare".
- `by_scale`: the appearance-controlled corpus is split by object scale (paper: train on
  s ∈ {0.15, 0.20}, test on s = 0.25); validation rows are a stratified slice of the train scales.
- `by_object`: a corpus of repeated contacts (several rows per object, `appearance_id` the
  object) is split by object: its objects, stratified on their mass-quantile class, are dealt
  into train/val/test, and every row follows its object, so no object is seen in training
  and tested.

`assert_trainable` is the guard every training rule calls: it refuses any id whose split is not
allowed for training (held-out `test` rows always; `val` unless the caller allows it).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tacgen_lib.io.schema import SchemaSettings, schema_fields

__all__ = [
    "SplitSettings",
    "SPLITS",
    "LeakageError",
    "make_splits",
    "assert_trainable",
    "ids_in_split",
    "split_size",
]

SPLITS = ("train", "val", "test")


class LeakageError(RuntimeError):
    """A training rule was handed rows that are held out."""


def split_size(n: int, fraction: float) -> int:
    """Rows a split of `fraction` takes from a stratified corpus of n rows (`make_splits`):
    round(fraction x n), at least 1; 0 when the fraction is 0."""
    return max(1, round(float(fraction) * int(n))) if fraction > 0 else 0


def _stratified_split(
    ids: np.ndarray, strata: np.ndarray, fractions: Mapping[str, float], seed: int
) -> np.ndarray:
    """train/val/test labels for `ids`, stratified on `strata` where each stratum allows it."""
    n = len(ids)
    out = np.empty(n, dtype=object)
    if n == 0:
        return out
    test_frac = float(fractions["test"])
    val_frac = float(fractions["val"])
    strata = pd.Series(strata).fillna("none").astype(str).to_numpy()

    def pooled(labels: np.ndarray, n_parts: int) -> np.ndarray | None:
        counts = pd.Series(labels).value_counts()
        labels = np.where(pd.Series(labels).map(counts).to_numpy() < n_parts, "rare", labels)
        counts = pd.Series(labels).value_counts()
        return labels if (counts >= n_parts).all() and len(counts) > 1 else None

    # imported here: every training script imports this module for `assert_trainable`, and
    # sklearn.model_selection costs ~0.65 s of import (scipy.stats) that they do not need
    from sklearn.model_selection import train_test_split

    idx = np.arange(n)
    rest, test = idx, np.array([], dtype=int)
    if test_frac > 0:
        strat = pooled(strata, 2)
        n_test = split_size(n, test_frac)
        if strat is not None and n_test < len(set(strat)):
            strat = None
        rest, test = train_test_split(idx, test_size=n_test, random_state=seed, stratify=strat)
    val = np.array([], dtype=int)
    if val_frac > 0 and len(rest) > 1:
        n_val = split_size(n, val_frac)
        strat = pooled(strata[rest], 2)
        if strat is not None and n_val < len(set(strat)):
            strat = None
        rest, val = train_test_split(rest, test_size=n_val, random_state=seed + 1, stratify=strat)
    out[rest] = "train"
    out[val] = "val"
    out[test] = "test"
    return out


def make_splits(manifest: pd.DataFrame, settings: SplitSettings) -> pd.DataFrame:
    """The split edge for a fused manifest, made as `settings` (config ``splits``) says.

    manifest: one row per sample with `sample_id`, `corpus`, `stratum` (and `scale` for corpora
        split by scale).
    settings.fractions: {"train", "val", "test"} shares for stratified corpora.
    settings.by_scale: corpus -> {"train": [scales], "test": [scales]}; for those corpora rows
        are split by scale, and `fractions["val"]` of the train-scale rows become validation
        rows.
    settings.by_object: corpus -> {"train", "val", "test"} shares of its objects and the
        "classes" they are stratified on (rows grouped by `appearance_id`, which the manifest
        must then hold with `mass`; the objects' mass-quantile classes); each class needs at
        least 2 objects.
    Returns `sample_id`, `corpus`, `split`, sorted by `sample_id`. Deterministic in
    ``settings.seed``.
    """
    seed, fractions = settings.seed, dict(settings.fractions)
    total = sum(fractions.values())
    if any(v < 0 for v in fractions.values()) or not np.isclose(total, 1.0):
        raise ValueError(f"split fractions must be non-negative and sum to 1, got {fractions}")
    by_scale, by_object = dict(settings.by_scale), dict(settings.by_object)
    for col in ("sample_id", "corpus", "stratum"):
        if col not in manifest.columns:
            raise ValueError(f"make_splits: the manifest has no column {col!r}")
    parts = []
    for corpus, rows in manifest.sort_values("sample_id").groupby("corpus", sort=True):
        ids = rows["sample_id"].to_numpy(dtype=object)
        strata = rows["stratum"].to_numpy(dtype=object)
        if corpus in by_scale:
            rule = by_scale[corpus]
            if "scale" not in rows.columns:
                raise ValueError(
                    f"make_splits: corpus {corpus!r} is split by scale but has no 'scale' column"
                )
            scale = rows["scale"].to_numpy(dtype=float)
            train_s = np.isin(np.round(scale, 6), np.round(np.asarray(rule["train"], float), 6))
            test_s = np.isin(np.round(scale, 6), np.round(np.asarray(rule["test"], float), 6))
            if not train_s.any() or not test_s.any():
                raise ValueError(
                    f"make_splits: corpus {corpus!r} has no rows at train scales {list(rule['train'])} "
                    f"or test scales {list(rule['test'])} (scales present: {sorted(set(scale.round(6)))})"
                )
            split = np.full(len(ids), "excluded", dtype=object)
            split[test_s] = "test"
            inner = _stratified_split(
                ids[train_s], strata[train_s], {"val": fractions["val"], "test": 0.0}, seed
            )
            split[train_s] = inner
        elif corpus in by_object:
            split = _object_split(rows, corpus, by_object[corpus], seed)
        else:
            split = _stratified_split(ids, strata, fractions, seed)
        parts.append(pd.DataFrame({"sample_id": ids, "corpus": corpus, "split": split}))
    if not parts:
        raise ValueError("make_splits: the manifest is empty")
    return pd.concat(parts, ignore_index=True).sort_values("sample_id", ignore_index=True)


def _object_split(
    rows: pd.DataFrame, corpus: str, rule: Mapping[str, float], seed: int
) -> np.ndarray:
    """The split of each row of one corpus split by object (`make_splits`' by_object)."""
    from tacgen_lib.corpus.objects import mass_quantile_classes, object_masses

    where = f"make_splits: corpus {corpus!r} (split by object)"
    n_classes = int(rule["classes"])
    fractions = {k: float(rule[k]) for k in SPLITS}
    total = sum(float(v) for v in fractions.values())
    if not np.isclose(total, 1.0):
        raise ValueError(f"{where}: object shares must sum to 1, got {dict(fractions)}")
    masses = object_masses(rows, where=where)
    classes = mass_quantile_classes(masses.to_numpy(), n_classes, where=where)
    counts = np.bincount(classes, minlength=n_classes)
    if counts.min() < 2:
        raise ValueError(
            f"{where}: mass class {int(np.argmin(counts))} of {n_classes} has "
            f"{int(counts.min())} object(s) of {len(masses)}; an object-level split needs at "
            "least 2 objects per class (one to train on, one to test), so the corpus needs "
            "more objects (n / contacts)"
        )
    objects = masses.index.to_numpy()
    labels = np.array([f"class{c}" for c in classes], dtype=object)
    object_split = _stratified_split(objects, labels, fractions, seed)
    return pd.Series(object_split, index=objects).reindex(rows["appearance_id"]).to_numpy()


def ids_in_split(
    splits: pd.DataFrame, split: str | Iterable[str], corpus: str | None = None
) -> np.ndarray:
    """Sample ids whose split is `split` (one name or several), optionally of one corpus."""
    names = {split} if isinstance(split, str) else set(split)
    unknown = names - set(SPLITS)
    if unknown:
        raise ValueError(f"unknown split(s) {sorted(unknown)}; splits are {SPLITS}")
    mask = splits["split"].isin(names)
    if corpus is not None:
        mask &= splits["corpus"] == corpus
    return splits.loc[mask, "sample_id"].to_numpy(dtype=object)


def assert_trainable(
    ids: Iterable[str],
    splits: pd.DataFrame,
    *,
    rule: str,
    allowed: Iterable[str] = ("train",),
) -> None:
    """Refuse to train on any id whose split is not in `allowed` (default: train only).

    Raises LeakageError naming the rule, how many rows leak, and the first offending sample_id.
    Ids missing from the split edge are refused too: an unsplit row cannot be proven safe.
    """
    allowed = set(allowed)
    if "test" in allowed:
        raise LeakageError(f"rule {rule}: held-out 'test' rows can never be allowed for training")
    ids = pd.Index(list(ids))
    split_of = splits.set_index("sample_id")["split"]
    found = split_of.reindex(ids)
    missing = found.isna()
    if missing.any():
        raise LeakageError(
            f"rule {rule}: {int(missing.sum())} training row(s) are not in the split edge, "
            f"e.g. sample_id {ids[np.flatnonzero(missing.to_numpy())[0]]!r}"
        )
    bad = ~found.isin(allowed)
    if bad.any():
        first = int(np.flatnonzero(bad.to_numpy())[0])
        raise LeakageError(
            f"rule {rule}: refusing to train on {int(bad.sum())} held-out row(s); "
            f"sample_id {ids[first]!r} is in split {found.iloc[first]!r} (allowed: {sorted(allowed)})"
        )


@dataclass(frozen=True)
@schema_fields("splits")
class SplitSettings(SchemaSettings):
    """How the splits are made (config ``splits``; `make_splits`): the `seed`, the train / val
    / test `fractions` of a stratified split, and the corpora split `by_scale` or `by_object`
    instead (corpus -> their scales or shares)."""
