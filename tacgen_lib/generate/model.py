"""The denoiser of the latent generator: a residual MLP over tactile feature vectors.

This module owns the network (after RCG's representation diffusion model: an MLP denoiser over
SSL feature vectors whose residual blocks add the time and condition embeddings, with a
zero-initialised output layer), the sinusoidal timestep embedding, the learned null condition
of classifier-free guidance (the standardisation of the target features and the numpy forward
pass that sampling uses live in `inference`, which does not import torch).

- Input x_t: a standardised tactile feature (d_t), the vision feature (d_v) as condition.
- Output: epsilon (``prediction = "eps"``) or v = sqrt(abar) eps - sqrt(1 - abar) x0
  (``prediction = "v"``, Salimans & Ho 2022); `sampling` converts both to (eps, x0).
- A condition row is replaced by the learned ``null_condition`` where ``drop`` is True
  (training: with probability p_uncond; sampling: the unconditional half of the CFG batch).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from tacgen_lib.generate import inference
from tacgen_lib.generate.inference import DenoiserArrays, Standardiser, fit_standardiser

__all__ = [
    "Denoiser",
    "Standardiser",
    "fit_standardiser",
    "sinusoidal_embedding",
]


def sinusoidal_embedding(t: Tensor, dim: int, max_period: float = 10_000.0) -> Tensor:
    """`inference.sinusoidal_embedding` of integer timesteps as a float32 tensor (B,) -> (B, dim)."""
    return torch.from_numpy(
        inference.sinusoidal_embedding(t.detach().cpu().numpy(), dim, max_period)
    )


class ResidualBlock(nn.Module):
    """x + MLP(LayerNorm(x) + emb): the time/condition embedding is added inside each block."""

    def __init__(self, width: int):
        super().__init__()
        self.norm = nn.LayerNorm(width)
        self.emb = nn.Linear(width, width)
        self.fc1 = nn.Linear(width, width)
        self.fc2 = nn.Linear(width, width)
        self.act = nn.SiLU()

    def forward(self, x: Tensor, emb: Tensor) -> Tensor:
        h = self.norm(x) + self.emb(emb)
        h = self.fc2(self.act(self.fc1(self.act(h))))
        return x + h


class Denoiser(nn.Module):
    """eps- (or v-) prediction residual MLP conditioned on the vision feature and the timestep."""

    def __init__(self, dim_t: int, dim_v: int, hidden: int, blocks: int, time_dim: int):
        super().__init__()
        self.dims = {
            "dim_t": dim_t,
            "dim_v": dim_v,
            "hidden": hidden,
            "blocks": blocks,
            "time_dim": time_dim,
        }
        self.time_dim = time_dim
        self.inp = nn.Linear(dim_t, hidden)
        self.time = nn.Sequential(nn.Linear(time_dim, hidden), nn.SiLU(), nn.Linear(hidden, hidden))
        self.cond = nn.Sequential(nn.Linear(dim_v, hidden), nn.SiLU(), nn.Linear(hidden, hidden))
        self.null_condition = nn.Parameter(torch.zeros(dim_v))
        self.blocks = nn.ModuleList(ResidualBlock(hidden) for _ in range(blocks))
        self.out_norm = nn.LayerNorm(hidden)
        self.out = nn.Linear(hidden, dim_t)
        nn.init.zeros_(self.out.weight)  # zero-initialised last layer (RCG): starts at eps = 0
        nn.init.zeros_(self.out.bias)

    def condition(self, cond: Tensor, drop: Tensor | None = None) -> Tensor:
        """cond (B, d_v) with the rows where ``drop`` is True replaced by the null condition."""
        if drop is None:
            return cond
        return torch.where(drop[:, None], self.null_condition[None, :].expand_as(cond), cond)

    def forward(self, x_t: Tensor, t: Tensor, cond: Tensor, drop: Tensor | None = None) -> Tensor:
        """x_t (B, d_t), t (B,) integer steps, cond (B, d_v); drop (B,) bool -> null condition."""
        cond = self.condition(cond, drop)
        # the embedding is formed on the CPU (numpy); on the CPU `.to` is no move, no copy
        time = sinusoidal_embedding(t, self.time_dim).to(device=x_t.device, dtype=x_t.dtype)
        emb = self.time(time) + self.cond(cond)
        h = self.inp(x_t)
        for block in self.blocks:
            h = block(h, emb)
        return self._head(h)

    def arrays(self) -> DenoiserArrays:
        """This module's weights for the numpy forward pass that sampling uses."""
        state = {k: v.detach().cpu().numpy() for k, v in self.state_dict().items()}
        return DenoiserArrays.from_state(state, self.dims)

    def _head(self, h: Tensor) -> Tensor:
        return self.out(torch.nn.functional.silu(self.out_norm(h)))
