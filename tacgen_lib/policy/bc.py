"""Behaviour cloning: an MLP from palpation features to the oracle's grip force.

Conditions differ only in the features (everything else matched: demonstrations, splits, MLP
depth and width, optimiser, epochs, batch, seed):

- ``v``: the frozen vision backbone's feature of the RGB context frame;
- ``vt_aligned``: v + the tactile frames projected by the alignment heads (one 128-d
  projection per frame, concatenated);
- ``vt_raw``: v + the frozen tactile backbone's features of the frames, concatenated;
- ``vt_null``: v + aligned tactile features of *another* episode (a fixed derangement inside
  each split): the negative control, which must fall to V-only level.

The target is log(oracle force); the MLP regresses it (MSE) and the policy grips at
exp(prediction). Inputs are standardised with the training rows' mean and sd.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from tacgen_lib.io import hashed
from tacgen_lib.optim import AdamW
from tacgen_lib.policy.settings import LEARNED_CONDITIONS

__all__ = ["condition_features", "null_pairing", "BCPolicy", "fit_bc", "save_bc", "load_bc"]


def null_pairing(ids: np.ndarray, splits: np.ndarray, seed: int) -> np.ndarray:
    """Index of the episode whose tactile features episode i gets in the null condition: a
    seeded derangement within each split (never itself, never across demos/held-out)."""
    out = np.arange(len(ids))
    rng = np.random.default_rng([seed, 0x0A11])
    for sp in np.unique(splits):
        idx = np.flatnonzero(splits == sp)
        if len(idx) < 2:
            raise ValueError(f"null pairing: split {sp!r} has {len(idx)} episode(s), need >= 2")
        shift = int(rng.integers(1, len(idx)))
        out[idx] = idx[np.roll(np.arange(len(idx)), shift)]
    return out


def condition_features(
    condition: str,
    v: np.ndarray,
    t_raw: np.ndarray,
    t_aligned: np.ndarray,
    null_index: np.ndarray,
) -> np.ndarray:
    """The policy input of `condition` (rows aligned with v)."""
    if condition == "v":
        return v
    if condition == "vt_aligned":
        return np.hstack([v, t_aligned])
    if condition == "vt_raw":
        return np.hstack([v, t_raw])
    if condition == "vt_null":
        return np.hstack([v, t_aligned[null_index]])
    raise ValueError(f"unknown policy condition {condition!r} (one of {LEARNED_CONDITIONS})")


def _mlp(d_in: int, hidden: int, layers: int) -> nn.Sequential:
    mods: list[nn.Module] = []
    d = d_in
    for _ in range(layers - 1):
        mods += [nn.Linear(d, hidden), nn.ReLU()]
        d = hidden
    mods.append(nn.Linear(d, 1))
    return nn.Sequential(*mods)


@dataclass
class BCPolicy:
    """A trained policy: the MLP and the standardisation of its inputs and target."""

    net: nn.Sequential
    mean: np.ndarray
    sd: np.ndarray
    y_mean: float
    y_sd: float

    def grip_force(self, x: np.ndarray) -> np.ndarray:
        """Grip force (N per pad) for feature rows x, computed where the network is."""
        dev = next(self.net.parameters()).device
        z = torch.from_numpy(((x - self.mean) / self.sd).astype(np.float32)).to(dev)
        self.net.eval()
        with torch.no_grad():
            y = self.net(z).cpu().numpy()[:, 0].astype(np.float64)
        return np.exp(y * self.y_sd + self.y_mean)


def fit_bc(
    x: np.ndarray,
    force: np.ndarray,
    *,
    hidden: int,
    layers: int,
    epochs: int,
    lr: float,
    weight_decay: float,
    batch_size: int,
    seed: int,
    device: torch.device | str,
) -> tuple[BCPolicy, list[float]]:
    """Fit the MLP (AdamW, MSE on standardised log force); returns the policy (on the CPU)
    and the per-epoch training loss. Bit-for-bit reproducible for the same inputs, seed and
    thread count on the CPU. `device`: where it trains (`tacgen_lib.runtime.device`); the
    network is initialised and the batches shuffled on the CPU, so only the arithmetic moves
    (none on the CPU)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.log(np.asarray(force, dtype=np.float64))
    mean, sd = x.mean(0), x.std(0) + 1e-6
    y_mean, y_sd = float(y.mean()), float(y.std() + 1e-6)
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    net = _mlp(x.shape[1], hidden, layers)
    dev = torch.device(device)
    net.to(dev)
    opt = AdamW(net.parameters(), lr=lr, weight_decay=weight_decay)
    xt = torch.from_numpy(((x - mean) / sd).astype(np.float32)).to(dev)
    yt = torch.from_numpy(((y - y_mean) / y_sd).astype(np.float32))[:, None].to(dev)
    losses = []
    for _ in range(epochs):
        perm = torch.randperm(len(xt), generator=gen)
        total = 0.0
        for i in range(0, len(xt), batch_size):
            b = perm[i : i + batch_size]
            loss = nn.functional.mse_loss(net(xt[b]), yt[b])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(b)
        losses.append(total / len(xt))
    net.to("cpu")
    return BCPolicy(net, mean, sd, y_mean, y_sd), losses


def save_bc(policy: BCPolicy, hidden: int, layers: int) -> bytes:
    """Serialise (torch.save of a plain dict) for an atomically written, hashed weights file."""
    buf = io.BytesIO()
    torch.save(
        {
            "state": policy.net.state_dict(),
            "mean": policy.mean,
            "sd": policy.sd,
            "y": [policy.y_mean, policy.y_sd],
            "hidden": hidden,
            "layers": layers,
        },
        buf,
    )
    return buf.getvalue()


def load_bc(path: str) -> BCPolicy:
    """Load a policy written by `save_bc` after checking its hash (tacgen_lib.io.hashed.verify)."""
    hashed.verify(path)
    obj = torch.load(path, weights_only=False)
    net = _mlp(len(obj["mean"]), obj["hidden"], obj["layers"])
    net.load_state_dict(obj["state"])
    return BCPolicy(net, obj["mean"], obj["sd"], *obj["y"])
