"""What a trained pixel generator (the pixel DDPM, Pix2Pix) is: its model and how it was trained.

`PixelFit` holds the fields both kinds share (the weights file of `tacgen_lib.generate.pixel.
weights` stores them); `PixelFit.from_training` builds one from the end of a fit (the model
with its best state, the `EarlyStopping` that chose it and the curve's rows).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Self

import pandas as pd
from torch import nn

from tacgen_lib.generate.stopping import EarlyStopping

__all__ = ["PixelFit"]


@dataclass(frozen=True, eq=False)
class PixelFit:
    """A trained pixel generator (eval mode) and how it was trained.

    curve: one row per evaluation (the kind's `CURVE_COLUMNS`; step 0 is the untrained model).
    best_step, best_val: the evaluation whose weights are kept and its validation score (the
    training score if there are no val rows); steps_run: the last step run; stopped_early:
    whether patience ran out.
    """

    model: nn.Module
    settings: Any
    seed: int
    size: tuple[int, int]
    curve: pd.DataFrame
    best_step: int
    best_val: float
    steps_run: int
    stopped_early: bool

    @classmethod
    def from_training(
        cls,
        model: nn.Module,
        stopper: EarlyStopping,
        curve: list[dict],
        columns: Sequence[str],
        *,
        settings: Any,
        seed: int,
        size: tuple[int, int],
        steps_run: int,
        **extra: Any,
    ) -> Self:
        """The fit of `model` (already restored: `EarlyStopping.restore`) whose best
        evaluation `stopper` chose; `curve` rows become a frame with `columns`; `extra`: the
        kind's own fields."""
        return cls(
            model=model,
            settings=settings,
            seed=int(seed),
            size=size,
            curve=pd.DataFrame(curve, columns=list(columns)),
            best_step=stopper.step,
            best_val=float(stopper.score),
            steps_run=steps_run,
            stopped_early=stopper.stopped,
            **extra,
        )
