"""tacgen_lib.optim.AdamW: bit-identical to torch.optim.AdamW, without importing torch._dynamo."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest
import torch

from tacgen_lib.optim import AdamW


def _model(seed: int) -> torch.nn.Module:
    torch.manual_seed(seed)
    return torch.nn.Sequential(
        torch.nn.Linear(7, 16), torch.nn.SiLU(), torch.nn.Linear(16, 3), torch.nn.LayerNorm(3)
    )


def _groups(model: torch.nn.Module, split: bool) -> list:
    if not split:
        return list(model.parameters())
    decay = [p for p in model.parameters() if p.ndim > 1]
    rest = [p for p in model.parameters() if p.ndim <= 1]
    return [{"params": decay}, {"params": rest, "weight_decay": 0.0}]


def _train(make_opt, fused, split, frozen_bias=False) -> list[torch.Tensor]:
    model = _model(0)
    if frozen_bias:  # a parameter that never gets a gradient
        model[2].bias.requires_grad_(False)
    opt = make_opt(_groups(model, split), lr=3e-3, weight_decay=0.05, fused=fused)
    gen = torch.Generator().manual_seed(1)
    for step in range(25):
        for group in opt.param_groups:  # lr changed between steps, as the training loops do
            group["lr"] = 3e-3 * (0.5 + 0.5 * (step % 5) / 4)
        x = torch.randn(32, 7, generator=gen)
        y = torch.randn(32, 3, generator=gen)
        loss = torch.mean((model(x) - y) ** 2)
        opt.zero_grad(set_to_none=step % 2 == 0)
        loss.backward()
        opt.step()
    return [p.detach().clone() for p in model.parameters()]


@pytest.mark.parametrize("fused", [True, None])
@pytest.mark.parametrize("split", [False, True])
@pytest.mark.parametrize("frozen_bias", [False, True])
def test_adamw_equals_torch_optim_adamw_bit_for_bit(fused, split, frozen_bias):
    ours = _train(AdamW, fused, split, frozen_bias)
    theirs = _train(torch.optim.AdamW, fused, split, frozen_bias)
    assert len(ours) == len(theirs)
    for a, b in zip(ours, theirs, strict=True):
        assert torch.equal(a, b)
    assert not torch.equal(ours[0], _model(0)[0].weight)  # it did train


def test_adamw_state_matches_torch_step_counter_and_moments():
    model_a, model_b = _model(0), _model(0)
    ours = AdamW(model_a.parameters(), lr=1e-2, fused=True)
    theirs = torch.optim.AdamW(model_b.parameters(), lr=1e-2, fused=True)
    x = torch.randn(8, 7, generator=torch.Generator().manual_seed(2))
    for m, opt in ((model_a, ours), (model_b, theirs)):
        for _ in range(3):
            opt.zero_grad()
            m(x).square().mean().backward()
            opt.step()
    for pa, pb in zip(model_a.parameters(), model_b.parameters(), strict=True):
        sa, sb = ours.state[pa], theirs.state[pb]
        assert sa["step"].dtype == sb["step"].dtype and float(sa["step"]) == 3.0
        assert torch.equal(sa["exp_avg"], sb["exp_avg"])
        assert torch.equal(sa["exp_avg_sq"], sb["exp_avg_sq"])


def test_adamw_refuses_empty_and_repeated_parameters():
    p = torch.nn.Parameter(torch.zeros(2))
    with pytest.raises(ValueError, match="empty"):
        AdamW([])
    with pytest.raises(ValueError, match="more than one group"):
        AdamW([{"params": [p]}, {"params": [p]}])


def test_training_with_adamw_does_not_import_dynamo():
    """The point of the module: a training step costs no torch._dynamo import (~1 s)."""
    code = textwrap.dedent(
        """
        import sys, torch
        from tacgen_lib.optim import AdamW
        m = torch.nn.Linear(4, 2)
        opt = AdamW(m.parameters(), lr=1e-3, fused=True)
        m(torch.ones(3, 4)).sum().backward()
        torch.nn.utils.clip_grad_norm_(list(m.parameters()), 1.0, foreach=True)
        opt.step()
        opt.zero_grad()
        print("torch._dynamo" in sys.modules)
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
