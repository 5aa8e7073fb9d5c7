"""Checks every in-workflow pretraining test shares (DINO, MAE, SimCLR): two runs of one
computation give the same backbone, bit for bit, and the curve's loss falls."""

from __future__ import annotations

import numpy as np
import torch


def assert_same_backbone(one, two) -> None:
    """Two pretraining results carry the same backbone state, key for key and bit for bit."""
    assert one.backbone_state.keys() == two.backbone_state.keys()
    for k, v in one.backbone_state.items():
        assert torch.equal(v, two.backbone_state[k]), k


def assert_loss_falls(curve: list[dict[str, float]], epochs: int) -> None:
    """One finite loss per epoch, in order, the last below the first (the objective is being
    minimised)."""
    assert [int(r["epoch"]) for r in curve] == list(range(epochs))
    losses = [r["loss"] for r in curve]
    assert all(np.isfinite(losses))
    assert losses[-1] < losses[0]
