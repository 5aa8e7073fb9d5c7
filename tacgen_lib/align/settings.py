"""The alignment stage's settings: one frozen object from config ``align`` (one per stage, read by `io.config.settings_from`).

`AlignSettings.from_config(config["align"])` reads what a grid cell's training needs (each
field's default and bounds are its key's in config/config.schema.yaml, `io.schema.setting`); the grid itself
(corpora, variants, seeds, taus, n_train) is expanded by the rules into wildcards, and τ and
the seed reach `heads.fit_heads` per cell. `AlignSettings.tiny()` is a seconds-long budget
for tests.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

from tacgen_lib.io.config import settings_from
from tacgen_lib.io.schema import check_settings, setting

__all__ = ["AlignSettings"]


@dataclass(frozen=True)
class AlignSettings:
    """How one alignment cell trains its heads (paper eq. 1); see `heads.fit_heads`.

    feature: the V and T vector column the heads align (``vit`` or ``pixel``).
    budget: ``"epochs"`` runs ``epochs * (n_train // batch)`` steps, ``"steps"`` runs `steps`.
    patience: evaluations without a better validation loss before stopping (0: never);
    eval_every: steps between validation evaluations.
    """

    feature: Literal["vit", "pixel"] = setting("align.features")
    budget: Literal["epochs", "steps"] = setting("align.budget")
    epochs: int = setting("align.epochs")
    steps: int = setting("align.steps")
    batch_size: int = setting("align.batch_size")
    lr: float = setting("align.lr")
    weight_decay: float = setting("align.weight_decay")
    warmup_frac: float = setting("align.warmup_frac")
    clip_grad: float = setting("align.clip_grad")
    patience: int = setting("align.patience")
    eval_every: int = setting("align.eval_every")

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def from_config(cls, align: Mapping[str, Any]) -> AlignSettings:
        """Settings from config ``align`` (the config key of `feature` is ``features``; the grid
        keys are the rules')."""
        return settings_from(
            cls, align, where="align", ignore=("corpora", "variants", "seeds", "taus", "n_train")
        )

    @classmethod
    def tiny(cls, **changes: Any) -> AlignSettings:
        """A budget of a few dozen steps on small batches, for tests; `changes` override."""
        small = cls(
            budget="steps", epochs=1, steps=30, batch_size=64, lr=1e-3, patience=0, eval_every=10
        )
        return replace(small, **changes)
