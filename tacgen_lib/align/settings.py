"""The alignment stage's settings: one frozen object from config ``align`` (one per stage, read by `io.config.settings_from`).

`AlignSettings.from_config(config["align"])` reads what a grid cell's training needs (its
fields, their types, defaults and bounds are the keys of ``align`` in config/config.schema.yaml,
`io.schema.schema_fields`); the grid itself (corpora, variants, seeds, taus, n_train) is
expanded by the rules into wildcards, and τ and the seed reach `heads.fit_heads` per cell. `AlignSettings.tiny()` is a seconds-long budget
for tests.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from tacgen_lib.io.schema import SchemaSettings, schema_fields

__all__ = ["AlignSettings"]


@dataclass(frozen=True)
@schema_fields(
    "align", skip=("corpora", "variants", "seeds", "taus", "n_train"), names={"features": "feature"}
)
class AlignSettings(SchemaSettings):
    """How one alignment cell trains its heads (paper eq. 1); see `heads.fit_heads`.

    feature: the V and T vector column the heads align (``vit`` or ``pixel``).
    budget: ``"epochs"`` runs ``epochs * (n_train // batch)`` steps, ``"steps"`` runs `steps`.
    patience: evaluations without a better validation loss before stopping (0: never);
    eval_every: steps between validation evaluations.
    """

    @classmethod
    def tiny(cls, **changes: Any) -> AlignSettings:
        """A budget of a few dozen steps on small batches, for tests; `changes` override."""
        small = cls(
            budget="steps", epochs=1, steps=30, batch_size=64, lr=1e-3, patience=0, eval_every=10
        )
        return replace(small, **changes)
