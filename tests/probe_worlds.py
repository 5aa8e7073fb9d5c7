"""Synthetic probe families and small probe settings shared by the probe tests (a plain
module: pytest puts tests/ on sys.path)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from tacgen_lib.probes import rows as ps_rows
from tacgen_lib.probes.settings import ProbeSettings


def synthetic_family_rows(kind: str, y: np.ndarray, n_train: int) -> ps_rows.FamilyRows:
    """A family's rows on corpus "sim", target "t": the first `n_train` of the labels `y`
    train, the rest test; ids s-0000, s-0001, ...; no strata, bands or unlabelled rows."""
    ids = np.array([f"s-{i:04d}" for i in range(len(y))], dtype=object)
    return ps_rows.FamilyRows(
        corpus="sim",
        target="t",
        kind=kind,
        train_ids=ids[:n_train],
        test_ids=ids[n_train:],
        y_train=y[:n_train],
        y_test=y[n_train:],
        strata_test=None,
        bands_test=None,
        n_unlabelled=0,
    )


#: the names of the control draws (`ProbeSettings`), each set to `controls` unless named
CONTROLS = ("train_resamples", "permutations", "label_permutations", "random_draws")


def probe_settings(
    kind: str,
    lambdas: Sequence[float],
    C: Sequence[float],
    *,
    folds: int,
    bootstrap: int,
    seed: int,
    controls: int = 0,
    **fields: Any,
) -> ProbeSettings:
    """`ProbeSettings` of `kind` on the λ / C grids, `controls` draws of every control (0:
    none) unless `fields` names it; `fields` sets any other field."""
    draws = dict.fromkeys(CONTROLS, controls) | fields
    grid = {"lambdas": tuple(lambdas), "C": tuple(C), "folds": folds, "bootstrap": bootstrap}
    return ProbeSettings(kind=kind, **grid, seed=seed, **draws)
