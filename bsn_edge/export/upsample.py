"""Exact bilinear upsampling as edge padding, one convolution and a depth-to-space shuffle.

Bilinear upsampling by an integer factor ``f`` (``align_corners=False``) makes each output pixel
from the 3 x 3 input neighbourhood of the pixel it falls in, with weights that depend only on
its position inside the ``f x f`` block; the frame's edge clamps like edge padding. So it is a
3 x 3 convolution to ``f * f`` channels followed by ``DepthToSpace``: the same numbers, but on
a CPU onnxruntime runs it several times faster than ``Resize`` on a one-channel map (which its
blocked layout pads to 8 or 16 channels). Bilinear upsamplings in a row (``x4`` then ``x2``) are
one linear map of the same 3 x 3 reach (each step stays within a coarse pixel's neighbours), so
they too are one convolution and one shuffle, at the cost of the last step's shuffle alone.
"""

from __future__ import annotations

import copy

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from bsn_edge.networks.upsample import Upsample


def bilinear_taps(factor: int) -> np.ndarray:
    """``[factor, 3]``: weights of input offsets -1, 0, +1 for each sub-position of a block."""
    taps = np.zeros((factor, 3), np.float64)
    for r in range(factor):
        c = (r + 0.5) / factor - 0.5   # the sub-position's source coordinate, relative to the block
        if c < 0:
            taps[r, 0], taps[r, 1] = -c, 1 + c
        else:
            taps[r, 1], taps[r, 2] = 1 - c, c
    return taps


def chained_taps(*factors: int) -> np.ndarray:
    """``[prod(factors), 3]``: :func:`bilinear_taps` of bilinear upsamplings by ``factors`` in turn
    (edges clamped at every step), read off the product of their 1-D matrices."""
    n = 5                    # coarse pixels: the middle one's block is clear of the edges
    total = np.eye(n)
    for f in factors:
        if int(f) != f or f < 1:
            raise ValueError(f"upsampling factors must be positive integers, got {factors}")
        m = total.shape[0]
        step = np.zeros((m * f, m))
        for i, row in enumerate(bilinear_taps(f)):
            for b in range(m):
                for k, w in zip((-1, 0, 1), row, strict=True):
                    step[b * f + i, min(max(b + k, 0), m - 1)] += w
        total = step @ total
    f = int(np.prod(factors))
    block = total[(n // 2) * f:(n // 2 + 1) * f]
    if np.abs(np.delete(block, [n // 2 - 1, n // 2, n // 2 + 1], axis=1)).max() > 1e-12:
        raise AssertionError("chained bilinear upsampling reached beyond a coarse pixel's neighbours")
    return block[:, n // 2 - 1:n // 2 + 2]


def edge_pad(x: Tensor) -> Tensor:
    """``x`` padded by one pixel repeating its edges; as slices and concatenations it exports to a
    static ONNX graph (``F.pad``'s replicate mode exports a chain of shape arithmetic)."""
    x = torch.cat([x[:, :, :1], x, x[:, :, -1:]], 2)
    return torch.cat([x[:, :, :, :1], x, x[:, :, :, -1:]], 3)


class ShuffleUpsample(nn.Module):
    """Bilinear ``x factor`` upsampling (``align_corners=False``) of any number of channels;
    ``ShuffleUpsample(4, 2)``: ``x4`` then ``x2``, in one step."""

    def __init__(self, *factors: int) -> None:
        super().__init__()
        factor = int(np.prod(factors)) if factors else 0
        if factor < 2:
            raise ValueError(f"ShuffleUpsample needs factors whose product is >= 2, got {factors}")
        t = chained_taps(*factors)
        kernel = np.einsum("ra,sb->rsab", t, t).reshape(factor * factor, 1, 3, 3)
        self.kernel: Tensor
        self.register_buffer("kernel", torch.from_numpy(kernel.astype(np.float32)))
        self.factor = factor

    def forward(self, x: Tensor) -> Tensor:
        n, c, h, w = x.shape
        if c != 1:   # channels as batch; one-channel maps (the heads') need no reshaping in the graph
            x = x.reshape(n * c, 1, h, w)
        y = F.pixel_shuffle(F.conv2d(edge_pad(x), self.kernel), self.factor)
        return y if c == 1 else y.reshape(n, c, h * self.factor, w * self.factor)


def with_shuffle_upsampling(model: nn.Module) -> nn.Module:
    """A copy of ``model`` with every ``Upsample`` of factor >= 2 replaced by ``ShuffleUpsample``."""
    model = copy.deepcopy(model)
    for name, mod in list(model.named_modules()):
        if isinstance(mod, Upsample) and mod.factor >= 2:
            parent, _, attr = name.rpartition(".")
            setattr(model.get_submodule(parent) if parent else model, attr, ShuffleUpsample(mod.factor))
    return model
