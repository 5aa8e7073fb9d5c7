"""The alignment stage's settings: one frozen object from config ``align`` (one per stage, read by `io.config.settings_from`).

`AlignSettings.from_config(config["align"])` reads what a grid cell's training needs (the
schema, config/config.schema.yaml, has already checked types and ranges); the grid itself
(corpora, variants, seeds, taus, n_train) is expanded by the rules into wildcards, and τ and
the seed reach `heads.fit_heads` per cell. `AlignSettings.tiny()` is a seconds-long budget
for tests.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

from tacgen_lib.io.config import settings_from

__all__ = ["AlignSettings"]


@dataclass(frozen=True)
class AlignSettings:
    """How one alignment cell trains its heads (paper eq. 1); see `heads.fit_heads`.

    feature: the V and T vector column the heads align (``vit`` or ``pixel``).
    budget: ``"epochs"`` runs ``epochs * (n_train // batch)`` steps, ``"steps"`` runs `steps`.
    patience: evaluations without a better validation loss before stopping (0: never);
    eval_every: steps between validation evaluations.
    """

    feature: Literal["vit", "pixel"] = "vit"
    budget: Literal["epochs", "steps"] = "epochs"
    epochs: int = 300
    steps: int = 6000
    batch_size: int = 256
    lr: float = 1e-4
    weight_decay: float = 0.01
    warmup_frac: float = 0.05
    clip_grad: float = 1.0
    patience: int = 8
    eval_every: int = 25

    def __post_init__(self) -> None:
        if self.feature not in ("vit", "pixel"):
            raise ValueError(f"align.features must be 'vit' or 'pixel', got {self.feature!r}")
        if self.budget not in ("epochs", "steps"):
            raise ValueError(f"align.budget must be 'epochs' or 'steps', got {self.budget!r}")
        for name, low in (("batch_size", 2), ("eval_every", 1), ("epochs", 0), ("steps", 0)):
            value = getattr(self, name)
            if int(value) != value or value < low:
                raise ValueError(f"align.{name} must be an integer >= {low}, got {value!r}")
        if int(self.patience) != self.patience or self.patience < 0:
            raise ValueError(f"align.patience must be an integer >= 0, got {self.patience!r}")
        for name in ("lr", "weight_decay", "warmup_frac", "clip_grad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"align.{name} must be a finite number >= 0, got {value!r}")

    @classmethod
    def from_config(cls, align: Mapping[str, Any]) -> AlignSettings:
        """Settings from config ``align`` (the config key of `feature` is ``features``; the grid
        keys are the rules')."""
        return settings_from(
            cls,
            align,
            where="align",
            rename={"feature": "features"},
            ignore=("corpora", "variants", "seeds", "taus", "n_train"),
        )

    @classmethod
    def tiny(cls, **changes: Any) -> AlignSettings:
        """A budget of a few dozen steps on small batches, for tests; `changes` override."""
        small = cls(
            budget="steps", epochs=1, steps=30, batch_size=64, lr=1e-3, patience=0, eval_every=10
        )
        return replace(small, **changes)
