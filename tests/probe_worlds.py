"""Synthetic probe families shared by the probe-protocol and backbone-family tests (a plain
module: pytest puts tests/ on sys.path)."""

from __future__ import annotations

import numpy as np

from tacgen_lib.probes import rows as ps_rows


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
