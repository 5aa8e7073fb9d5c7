"""The symmetric InfoNCE loss with in-batch negatives (paper eq. 1).

`info_nce` is ``0.5 * (CE(z_v z_t^T / tau, arange) + CE(z_t z_v^T / tau, arange))``, computed
with `torch.nn.functional.log_softmax` (a log-sum-exp with max shift) in float32;
`info_nce_reference` is an independent float64 plain-loop version the tests compare it with.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor


def _check_pairs(z_v: Tensor, z_t: Tensor, tau: float, where: str) -> None:
    if z_v.ndim != 2 or z_t.ndim != 2 or z_v.shape != z_t.shape:
        raise ValueError(
            f"{where}: expected two (B, d) tensors of the same shape (row i of each is a "
            f"positive pair), got {tuple(z_v.shape)} and {tuple(z_t.shape)}"
        )
    if z_v.shape[0] < 1:
        raise ValueError(f"{where}: empty batch; pass at least one pair")
    try:
        ok = math.isfinite(float(tau)) and float(tau) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{where}: temperature tau must be a finite number > 0, got {tau!r}")


def info_nce(z_v: Tensor, z_t: Tensor, tau: float) -> Tensor:
    """Symmetric InfoNCE over in-batch negatives (paper eq. 1).

    z_v, z_t: (B, d) projections, normally l2-normalised (the heads' outputs); row i of each is
    a positive pair and the other B-1 rows of the other modality are its negatives.
    Returns ``0.5 * (CE(z_v z_t^T / tau, arange(B)) + CE(z_t z_v^T / tau, arange(B)))``.
    The logits are formed in float32 and reduced by `F.log_softmax` over rows (v->t) and over
    columns (t->v), i.e. cross-entropy with a max-shifted log-sum-exp, so tau down to 0.01
    stays finite; a batch of one gives exactly 0.
    """
    _check_pairs(z_v, z_t, tau, "info_nce")
    logits = (z_v.float() @ z_t.float().T) / tau
    # CE(L, arange) = -mean(diag(log_softmax(L, dim=1))); CE(L^T, arange) is the same over
    # dim=0, which avoids materialising the transpose.
    v2t = F.log_softmax(logits, dim=1).diagonal()
    t2v = F.log_softmax(logits, dim=0).diagonal()
    return -0.5 * (v2t.mean() + t2v.mean())


def info_nce_reference(z_v: Tensor, z_t: Tensor, tau: float) -> Tensor:
    """Reference for `info_nce`, for tests: float64, plain loops over pairs, autograd-able.

    Every similarity is an explicit float64 dot product; each row's log-sum-exp is written out
    with its max shift. It shares no code with `info_nce` (no log_softmax, no matmul).
    """
    _check_pairs(z_v, z_t, tau, "info_nce_reference")
    zv, zt = z_v.double(), z_t.double()
    b = zv.shape[0]
    sim = [[torch.dot(zv[i], zt[j]) / tau for j in range(b)] for i in range(b)]

    def neg_log_softmax_diag(rows: list[list[Tensor]]) -> Tensor:
        total = torch.zeros((), dtype=torch.float64)
        for i, row in enumerate(rows):
            m = max(float(x.detach()) for x in row)
            s = torch.zeros((), dtype=torch.float64)
            for x in row:
                s = s + torch.exp(x - m)
            total = total + (m + torch.log(s) - row[i])
        return total / len(rows)

    v2t = neg_log_softmax_diag(sim)
    t2v = neg_log_softmax_diag([[sim[i][j] for i in range(b)] for j in range(b)])
    return 0.5 * (v2t + t2v)
