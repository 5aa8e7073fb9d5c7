"""AdamW for every training rule, through torch's functional form.

This module owns `AdamW`: the update of ``torch.optim.AdamW`` (same defaults, same state, the
same kernels) computed by torch's functional API ``torch.optim.adamw.adamw``, without the
``torch.optim.Optimizer`` class.

Why: the class imports ``torch._dynamo`` the first time it is used (``add_param_group`` is
wrapped by ``torch._disable_dynamo``, and every ``step`` runs ``torch._dynamo.graph_break()``).
That import costs ~1 s per process on these CPUs, and the default DAG starts ~30 training
processes (alignment heads, generators, policies, the backbone), each paying it for an
optimiser that never compiles anything. The functional API performs the same computation
without that import.

The update is tested bit-identical to ``torch.optim.AdamW`` (fused and single-tensor, several
parameter groups, lr changed between steps, parameters without a gradient): `tests/test_optim.py`.
Only what the project uses is supported: no amsgrad, no maximize, no capturable/differentiable
modes, no optimiser state_dict (no rule resumes an optimiser).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch
from torch import Tensor
from torch.optim.adamw import adamw as adamw_update

__all__ = ["AdamW"]


class AdamW:
    """``torch.optim.AdamW(params, lr, betas, eps, weight_decay, fused=...)`` without the class.

    `params`: tensors, or dicts with ``"params"`` and per-group overrides (like torch's
    parameter groups). ``param_groups`` is a list of dicts whose ``"lr"`` the caller may set
    between steps, as with torch's optimisers. `fused`: torch's fused single-kernel update
    (``True``) or torch's default for CPU tensors (``None``: the single-tensor loop).
    """

    def __init__(
        self,
        params: Iterable[Tensor] | Iterable[dict[str, Any]],
        *,
        lr: float = 1e-3,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
        weight_decay: float = 1e-2,
        fused: bool | None = None,
    ) -> None:
        defaults = {"lr": lr, "betas": tuple(betas), "eps": eps, "weight_decay": weight_decay}
        items = list(params)
        if not items:
            raise ValueError("AdamW: got an empty parameter list")
        groups = items if isinstance(items[0], dict) else [{"params": items}]
        self.param_groups: list[dict[str, Any]] = []
        seen: set[int] = set()
        for g in groups:
            group = {**defaults, **g, "params": list(g["params"])}
            for p in group["params"]:
                if id(p) in seen:
                    raise ValueError("AdamW: a parameter appears in more than one group")
                seen.add(id(p))
            self.param_groups.append(group)
        self.fused = fused
        self.state: dict[Tensor, dict[str, Tensor]] = {}

    def zero_grad(self, set_to_none: bool = True) -> None:
        """Drop (or zero) every parameter's gradient, as ``Optimizer.zero_grad``."""
        for group in self.param_groups:
            for p in group["params"]:
                if p.grad is None:
                    continue
                if set_to_none:
                    p.grad = None
                else:
                    p.grad.detach_().zero_()

    def _state(self, p: Tensor) -> dict[str, Tensor]:
        """The lazily created state of `p`, created as ``torch.optim.Adam._init_group`` does."""
        state = self.state.get(p)
        if state is None:
            state = {
                # torch hosts `step` as a float32 0-d tensor on the parameter's device when
                # fused, else as a CPU scalar in the default dtype
                "step": (
                    torch.zeros((), dtype=torch.float32, device=p.device)
                    if self.fused
                    else torch.tensor(0.0, dtype=torch.get_default_dtype(), device="cpu")
                ),
                "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                "exp_avg_sq": torch.zeros_like(p, memory_format=torch.preserve_format),
            }
            self.state[p] = state
        return state

    @torch.no_grad()
    def step(self) -> None:
        """One AdamW update of every parameter that has a gradient."""
        for group in self.param_groups:
            params = [p for p in group["params"] if p.grad is not None]
            if not params:
                continue
            if any(p.grad.is_sparse for p in params):
                raise RuntimeError("AdamW: sparse gradients are not supported")
            states = [self._state(p) for p in params]
            beta1, beta2 = group["betas"]
            adamw_update(
                params,
                [p.grad for p in params],
                [s["exp_avg"] for s in states],
                [s["exp_avg_sq"] for s in states],
                [],
                [s["step"] for s in states],
                foreach=None,
                fused=self.fused,
                has_complex=any(torch.is_complex(p) for p in params),
                amsgrad=False,
                beta1=beta1,
                beta2=beta2,
                lr=group["lr"],
                weight_decay=group["weight_decay"],
                eps=group["eps"],
                maximize=False,
            )
