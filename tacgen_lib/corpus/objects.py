"""Objects of a corpus of repeated contacts (YCB-Sight-like): which rows are one object, and
the objects' mass-quantile classes (the transfer probe's label, and the object-level split's
strata).

A simulated paired corpus with ``contacts`` = c > 1 holds c rows per object, all with the
object's index in ``appearance_id`` (tacgen_lib.corpus.sim.samples); an object's label is one
value, shared by its rows.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["MASS_CLASS_NAMES", "mass_class_names", "mass_quantile_classes", "object_masses"]

#: names of the classes of a three-way split (the paper's 3-class mass quantiles)
MASS_CLASS_NAMES = ("light", "medium", "heavy")


def mass_class_names(n_classes: int) -> tuple[str, ...]:
    """Readable names of `n_classes` mass-quantile classes, lightest first."""
    if n_classes == 3:
        return MASS_CLASS_NAMES
    return tuple(f"q{k + 1}" for k in range(n_classes))


def object_masses(rows: pd.DataFrame, *, where: str) -> pd.Series:
    """One mass per object (index: ``appearance_id``, sorted) from rows with ``appearance_id``
    and ``mass``. Raises ValueError naming `where` and the object if its rows disagree."""
    for col in ("appearance_id", "mass"):
        if col not in rows.columns:
            raise ValueError(f"{where}: no column {col!r} (objects need appearance_id and mass)")
    groups = rows.groupby("appearance_id", sort=True)["mass"]
    spread = groups.max() - groups.min()
    if (spread > 0).any():
        bad = int(spread.index[np.argmax(spread.to_numpy() > 0)])
        raise ValueError(
            f"{where}: the rows of object {bad} (appearance_id) have different masses; "
            "a row's object must be one physical object"
        )
    return groups.first()


def mass_quantile_classes(mass: np.ndarray, n_classes: int, *, where: str) -> np.ndarray:
    """Class 0..n_classes-1 of each object by the quantiles of the objects' masses
    (``pandas.qcut``: equal-count bins, edges at the mass quantiles, right-inclusive).

    Raises ValueError naming `where` when there are fewer objects than classes or when tied
    masses make two quantile edges equal.
    """
    mass = np.asarray(mass, dtype=np.float64)
    if n_classes < 2:
        raise ValueError(f"{where}: need at least 2 mass classes, got {n_classes}")
    if mass.size < n_classes:
        raise ValueError(
            f"{where}: {mass.size} object(s) cannot fill {n_classes} mass-quantile classes"
        )
    if not np.isfinite(mass).all():
        raise ValueError(f"{where}: an object's mass is not finite")
    try:
        classes = pd.qcut(mass, n_classes, labels=False)
    except ValueError as err:  # duplicate edges: tied masses
        raise ValueError(
            f"{where}: the objects' masses tie at a quantile edge, so {n_classes} classes "
            f"cannot be told apart ({err})"
        ) from None
    return np.asarray(classes, dtype=np.int64)
