"""Early stopping on a validation score, shared by every generator's training loop (the latent
DDPM, the pixel DDPM, Pix2Pix).

`EarlyStopping` keeps the best-scoring state seen so far (a deep copy of a module's state dict,
lower is better) and says when ``patience`` evaluations in a row have not beaten it (patience 0:
never). It starts from the module's initial state with a given score (the untrained model's
validation score where one is measured, else infinity), so a run that never improves ends on
its initial weights. `EarlyStopping.restore` ends a fit on that best state.
"""

from __future__ import annotations

import copy
import math
from typing import Any

from torch import nn

__all__ = ["EarlyStopping"]


class EarlyStopping:
    """The best state so far and the stop decision (module docstring).

    Attributes: ``score`` and ``step`` of the best evaluation, its ``state`` (a deep copy of the
    module's state dict), ``stopped`` once patience ran out.
    """

    def __init__(self, module: nn.Module, patience: int, score: float = math.inf) -> None:
        self.patience = int(patience)
        self.score, self.step = float(score), 0
        self.state: dict[str, Any] = copy.deepcopy(module.state_dict())
        self.bad, self.stopped = 0, False

    def update(self, score: float, step: int, module: nn.Module) -> bool:
        """Record one evaluation: a score below the best keeps `module`'s state; otherwise one
        more evaluation without improvement. True when training should stop."""
        if score < self.score:
            self.score, self.step = score, step
            self.state, self.bad = copy.deepcopy(module.state_dict()), 0
            return False
        self.bad += 1
        self.stopped = bool(self.patience and self.bad >= self.patience)
        return self.stopped

    def restore(self, module: nn.Module) -> nn.Module:
        """The end of every fit: `module` with the best state loaded, in eval mode, on the CPU
        (the same module, returned)."""
        module.load_state_dict(self.state)
        module.eval()
        module.to("cpu")
        return module
