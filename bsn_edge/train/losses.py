"""Losses of BlindSpotNet training (paper, Section 4)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from bsn_edge.models.bsn import MAX_DEPTH_M, MIN_DEPTH_M


def masked_bce(logits: Tensor, target: Tensor, valid: Tensor) -> Tensor:
    """Binary cross-entropy averaged over the pixels where ``valid`` (the visibility mask V) is set;
    pixels outside V contribute nothing. Zero when no pixel is valid."""
    loss = F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    v = valid.to(loss.dtype)
    return (loss * v).sum() / v.sum().clamp_min(1.0)


def pairwise_similarity(feats: Tensor, grid: tuple[int, int]) -> Tensor:
    """``[N, P, P]`` cosine similarities between the ``P = gh * gw`` patches of ``feats``
    (features averaged over each patch)."""
    f = F.adaptive_avg_pool2d(feats, grid).flatten(2)     # [N, C, P]
    f = F.normalize(f, dim=1)
    return f.transpose(1, 2) @ f


def distillation_loss(student: Tensor, teacher: Tensor, grid: tuple[int, int] = (8, 16)) -> Tensor:
    """Pairwise-similarity distillation (paper eq. 3): mean squared difference of the students' and
    the teacher's patch-similarity matrices. Channel counts and sizes may differ."""
    return F.mse_loss(pairwise_similarity(student, grid), pairwise_similarity(teacher.detach(), grid))


def depth_loss(pred: Tensor, target: Tensor, sky: Tensor | None = None) -> Tensor:
    """L1 on log depth over pixels with depth; sky pixels (when given) are taught as far."""
    t = target.clamp(MIN_DEPTH_M, MAX_DEPTH_M)
    valid = target > 0
    if sky is not None:
        t = torch.where(sky, torch.full_like(t, MAX_DEPTH_M), t)
        valid = valid | sky
    err = (pred.clamp_min(1e-3).log() - t.log()).abs()
    v = valid.to(err.dtype)
    return (err * v).sum() / v.sum().clamp_min(1.0)
