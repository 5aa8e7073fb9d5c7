"""DINO's targets and losses (DINOv2's recipe): the teacher's centring and sharpening, or
Sinkhorn-Knopp, the student-teacher cross-entropy, the KoLeo regulariser, and the diagnostics
that say whether the teacher is collapsing.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor


def _check_logits(student_out: Tensor, teacher_out: Tensor) -> None:
    if student_out.ndim != 3 or teacher_out.ndim != 3:
        raise ValueError(
            f"dino_loss: expected (crops, batch, K) logits, got student {tuple(student_out.shape)}"
            f" and teacher {tuple(teacher_out.shape)}"
        )
    n_s, b, k = student_out.shape
    n_t = teacher_out.shape[0]
    if teacher_out.shape[1:] != (b, k) or n_t > n_s:
        raise ValueError(
            f"dino_loss: teacher {tuple(teacher_out.shape)} does not match student "
            f"{tuple(student_out.shape)} (need same batch and K, teacher crops <= student crops)"
        )
    if n_s == n_t == 1:
        raise ValueError("dino_loss: need at least one student crop the teacher did not see")


def dino_cross_entropy(
    student_out: Tensor, teacher_probs: Tensor, student_temp: float
) -> tuple[Tensor, Tensor, Tensor]:
    """DINO cross-entropy against given teacher targets: (loss, teacher entropy, KL).

    student_out: (S, B, K) student logits for S crops, the first T of which are the global
    crops the teacher saw; teacher_probs: (T, B, K) teacher distributions (rows sum to 1, from
    `sinkhorn_knopp` or centring + sharpening). The student's distribution is
    log_softmax(student / student_temp). The loss averages -sum_k p_t log p_s over all
    (teacher crop t, student crop s) pairs with s != t and over the batch; the per-sample
    teacher entropy and KL(teacher || student) are averaged the same way (loss = entropy + KL).
    """
    _check_logits(student_out, teacher_probs)
    if not 0 < student_temp:
        raise ValueError(f"dino_loss: student temperature must be > 0, got {student_temp}")
    n_s, b, _ = student_out.shape
    n_t = teacher_probs.shape[0]
    pair_mask = torch.ones(n_t, n_s, dtype=torch.bool, device=student_out.device)
    diagonal = torch.arange(n_t, device=student_out.device)
    pair_mask[diagonal, diagonal] = False
    log_p_s = F.log_softmax(student_out / student_temp, dim=-1)
    # cross-entropy for every (teacher crop, student crop) pair, averaged over the batch
    ce = -torch.einsum("tbk,sbk->ts", teacher_probs, log_p_s) / b
    entropy_t = _entropy(teacher_probs).mean(-1)  # (T,)
    n_pairs = pair_mask.sum()
    loss = ce[pair_mask].sum() / n_pairs
    entropy = (entropy_t[:, None].expand(n_t, n_s)[pair_mask]).sum() / n_pairs
    return loss, entropy, loss - entropy


def _entropy(p: Tensor) -> Tensor:
    """Shannon entropy (nats) over the last axis, 0 log 0 = 0."""
    return -torch.special.xlogy(p, p).sum(-1)


def dino_loss_terms(
    student_out: Tensor,
    teacher_out: Tensor,
    center: Tensor,
    student_temp: float,
    teacher_temp: float,
) -> tuple[Tensor, Tensor, Tensor]:
    """DINO cross-entropy with a centred teacher (DINO v1): (loss, teacher entropy, KL).

    teacher_out: (T, B, K) teacher logits; center: (K,) or (1, K). The teacher distribution is
    softmax((teacher - center) / teacher_temp); see `dino_cross_entropy` for the rest.
    Log-sum-exp throughout, so constant, identical or single-sample batches and large logits
    stay finite.
    """
    _check_logits(student_out, teacher_out)
    if not (0 < teacher_temp and 0 < student_temp):
        raise ValueError(f"dino_loss: temperatures must be > 0, got {student_temp}, {teacher_temp}")
    p_t = centre_and_sharpen(teacher_out, center, teacher_temp)
    return dino_cross_entropy(student_out, p_t, student_temp)


def centre_and_sharpen(teacher_out: Tensor, center: Tensor, teacher_temp: float) -> Tensor:
    """DINO v1 teacher targets: softmax((teacher_out - center) / teacher_temp) over K."""
    k = teacher_out.shape[-1]
    return F.softmax((teacher_out - center.reshape(1, 1, k)) / teacher_temp, dim=-1)


def sinkhorn_knopp(teacher_out: Tensor, teacher_temp: float, n_iterations: int) -> Tensor:
    """Sinkhorn-Knopp centring of teacher logits (SwAV; DINOv2's replacement for the centre).

    teacher_out: (..., K) logits; all leading axes together are the N rows of one batch (DINOv2
    normalises both global crops jointly). Starting from Q = exp(logits / teacher_temp), each
    iteration rescales every prototype (column) to total mass N/K and then every row to mass 1,
    as DINOv2's `sinkhorn_knopp_teacher`; the result (same shape) has rows summing to 1 exactly
    and columns approaching N/K (equipartition) as n_iterations grows. Computed in the log
    domain, so huge logits and small temperatures stay finite. A batch whose rows are all equal
    gets uniform rows, which is why SK alone does not prevent representation collapse (see
    `koleo_loss`).
    """
    if not 0 < teacher_temp:
        raise ValueError(f"sinkhorn_knopp: teacher_temp must be > 0, got {teacher_temp}")
    if n_iterations < 1:
        raise ValueError(f"sinkhorn_knopp: n_iterations must be >= 1, got {n_iterations}")
    shape = teacher_out.shape
    log_q = (teacher_out.reshape(-1, shape[-1]) / teacher_temp).float()
    n, k = log_q.shape
    for _ in range(n_iterations):
        log_q = log_q - torch.logsumexp(log_q, dim=0, keepdim=True) + math.log(n / k)
        log_q = log_q - torch.logsumexp(log_q, dim=1, keepdim=True)
    return log_q.exp().reshape(shape).to(teacher_out.dtype)


def koleo_loss(features: Tensor, eps: float = 1e-8) -> Tensor:
    """KoLeo regulariser (DINOv2, after Sablayrolles et al. 2019): -mean_i log d(x_i, NN(x_i)).

    features: (B, D), l2-normalised here; d is the Euclidean distance from each row to its
    nearest other row (torch pairwise_distance with `eps`, as DINOv2). Minimising it spreads
    the batch over the sphere (the Kozachenko-Leonenko entropy estimator, up to constants).
    Identical rows give -log(~eps*sqrt(D)), large but finite with finite gradients; a batch of
    one row has no neighbour and gives 0.
    """
    if features.ndim != 2:
        raise ValueError(f"koleo_loss: expected (batch, dim) features, got {tuple(features.shape)}")
    b = features.shape[0]
    if b < 2:
        return features.sum() * 0.0
    x = F.normalize(features, dim=-1, eps=eps)
    with torch.no_grad():
        dots = x @ x.T
        dots.fill_diagonal_(-2.0)  # never its own neighbour (cosines are >= -1)
        nn_idx = dots.argmax(dim=1)
    return -torch.log(F.pairwise_distance(x, x[nn_idx], p=2, eps=eps) + eps).mean()


def dino_loss(
    student_out: Tensor,
    teacher_out: Tensor,
    center: Tensor,
    student_temp: float,
    teacher_temp: float,
) -> Tensor:
    """DINO self-distillation loss (see `dino_loss_terms` for shapes and definition)."""
    return dino_loss_terms(student_out, teacher_out, center, student_temp, teacher_temp)[0]


CURVE_MEANS = (
    "loss",
    "teacher_entropy",
    "kl",
    "koleo",
    "teacher_batch_entropy",
    "teacher_cls_cosine",
)


def collapse_diagnostics(teacher_probs: Tensor, teacher_cls: Tensor) -> dict[str, float]:
    """Two collapse read-outs of one teacher batch (averaged over its global crops).

    teacher_probs: (T, B, K) teacher targets; teacher_cls: (T, B, D) teacher CLS features.
    teacher_batch_entropy: entropy of the batch-mean target, H(mean_b p_b). With the per-sample
    entropy mean_b H(p_b) it brackets the two collapses: one-prototype collapse has both near 0,
    uniform collapse both near ln K; a healthy teacher has per-sample low and batch-mean high
    (their difference is the mutual information between image and prototype, <= ln B).
    teacher_cls_cosine: mean cosine between the CLS features of different images (-> 1 when the
    representation collapses to a constant).
    """
    if teacher_probs.ndim != 3 or teacher_cls.ndim != 3:
        raise ValueError(
            f"collapse_diagnostics: expected (crops, batch, .) tensors, got "
            f"{tuple(teacher_probs.shape)} and {tuple(teacher_cls.shape)}"
        )
    batch_h = _entropy(teacher_probs.double().mean(dim=1)).mean()
    b = teacher_cls.shape[1]
    if b < 2:
        cos = torch.tensor(1.0, dtype=torch.float64)
    else:
        z = F.normalize(teacher_cls.double(), dim=-1, eps=1e-12)
        gram = z @ z.transpose(1, 2)  # (T, B, B)
        cos = (gram.sum((1, 2)) - gram.diagonal(dim1=1, dim2=2).sum(-1)) / (b * (b - 1))
        cos = cos.mean()
    return {"teacher_batch_entropy": float(batch_h), "teacher_cls_cosine": float(cos)}
