"""Losses of BlindSpotNet training (paper, Section 4)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from bsn_edge.networks.bsn import MAX_DEPTH_M, MIN_DEPTH_M
from bsn_edge.semantics import IGNORE


def masked_bce(logits: Tensor, target: Tensor, valid: Tensor, weight: Tensor | None = None) -> Tensor:
    """Binary cross-entropy averaged over the pixels where ``valid`` (the visibility mask V) is set;
    pixels outside V contribute nothing. Zero when no pixel is valid.

    ``weight`` (broadcastable to ``logits``, optional) multiplies each pixel's term; the sum is still
    divided by the number of valid pixels, so a weight of 1 everywhere is the plain mean."""
    loss = F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    v = valid.to(loss.dtype)
    w = v if weight is None else v * weight
    return (loss * w).sum() / v.sum().clamp_min(1.0)


def visible_out_to(visibility: Tensor, depth: Tensor, semantic: Tensor, range_m: float) -> Tensor:
    """The visibility mask V ([N, 1, H, W]) widened to every pixel the clip sees (``semantic``
    [N, H, W] not ignored: inside the clip's view, off the car's hood) whose exact ``depth``
    ([N, 1, H, W], metres, 0 = none) is under ``range_m``."""
    seen = (semantic != IGNORE)[:, None]
    return torch.maximum(visibility, (seen & (depth > 0) & (depth < range_m)).to(visibility.dtype))


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


def depth_loss(pred: Tensor, target: Tensor, sky: Tensor | None = None, weight: Tensor | None = None,
               grad_scales: int = 0, free_scale: Tensor | None = None) -> Tensor:
    """L1 on log depth over pixels with depth; sky pixels (when given) are taught as far.

    ``weight`` ([N, 1, H, W], optional) weighs each pixel (e.g. more on cars and people, which
    cover few pixels but carry the distances on the bus). ``grad_scales`` > 0 adds the
    multi-scale gradient-matching term of Li & Snavely (MegaDepth, 2018): the L1 of the
    horizontal and vertical differences of the log-depth error at 1, 1/2, 1/4 ... resolution,
    which is zero for a prediction that is right up to a constant factor and large where an
    object's edge is blurred into the road behind it.

    ``free_scale`` ([N] bool, optional) marks samples whose depth is taught only up to a factor of
    their own: their log-depth error is taken about its (weighted) mean. A picture warped with a
    guessed field of view shows the scene at a scale it cannot tell (a longer lens looks like a
    nearer road), so its true metric depth is not in it to learn."""
    t = target.clamp(MIN_DEPTH_M, MAX_DEPTH_M)
    valid = target > 0
    if sky is not None:
        t = torch.where(sky, torch.full_like(t, MAX_DEPTH_M), t)
        valid = valid | sky
    r = pred.clamp_min(1e-3).log() - t.log()
    w = valid.to(r.dtype) if weight is None else valid.to(r.dtype) * weight
    if free_scale is not None and bool(free_scale.any()):
        mean = (r * w).sum(dim=(1, 2, 3), keepdim=True) / w.sum(dim=(1, 2, 3), keepdim=True).clamp_min(1e-6)
        r = r - mean * free_scale.to(r.dtype).view(-1, 1, 1, 1)
    loss = (r.abs() * w).sum() / w.sum().clamp_min(1e-6)
    for k in range(grad_scales):
        s = 2 ** k
        rs, ws = r[..., ::s, ::s], w[..., ::s, ::s]
        for dim in (-1, -2):
            n = rs.shape[dim] - 1
            d = (rs.narrow(dim, 1, n) - rs.narrow(dim, 0, n)).abs()
            pair = ws.narrow(dim, 1, n) * ws.narrow(dim, 0, n)     # both ends valid (and weighted)
            loss = loss + (d * pair).sum() / pair.sum().clamp_min(1e-6) / grad_scales
    return loss
