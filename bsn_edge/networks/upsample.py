"""Bilinear upsampling by an integer factor, as a module so an exporter can swap in an equivalent."""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor, nn


class Upsample(nn.Module):
    """``F.interpolate(x, scale_factor=factor, mode="bilinear", align_corners=False)``.

    Holds no weights, so checkpoints are the same with or without it; ``bsn_edge.export``
    replaces it with an exact convolution + depth-to-space form that CPUs run faster.
    """

    def __init__(self, factor: int) -> None:
        super().__init__()
        if int(factor) != factor or factor < 1:
            raise ValueError(f"upsampling factor must be a positive integer, got {factor}")
        self.factor = int(factor)

    def forward(self, x: Tensor) -> Tensor:
        if self.factor == 1:
            return x
        return F.interpolate(x, scale_factor=self.factor, mode="bilinear", align_corners=False)

    def extra_repr(self) -> str:
        return f"factor={self.factor}"
