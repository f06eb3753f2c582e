"""A strided stem convolution on a space-to-depth input: the same numbers, in a faster form.

A ``k x k`` convolution of stride 2 (``k`` odd, padding ``k // 2``) on 3 channels is a
``(k + 1) / 2``-square convolution of stride 1 on the 12 channels of the input's 2 x 2 blocks
(``pixel_unshuffle``), once its kernel is grown by a zero row and column (in front or behind,
so that it starts on a block) and cut into blocks.
onnxruntime's quantized convolution gathers 12 channels at a time far faster than 3 and needs no
stride. The input side becomes one fixed strided convolution from the uint8 frame: the
``1 / input_scale`` shrink (a box average, which is what bilinear halving is), the channel flip,
the normalisation and the block layout, followed by the zero padding the stem had.
"""

from __future__ import annotations

from typing import cast

import torch
import torch.nn.functional as F
from torch import Tensor, nn

BLOCK = 2      # the stem's stride, and so the side of the blocks


def fits(conv: nn.Module) -> bool:
    """Whether ``conv`` is a stem this rewrite applies to: stride 2, odd square kernel, padding
    of half the kernel, no dilation, groups or bias."""
    return (isinstance(conv, nn.Conv2d) and conv.stride == (BLOCK, BLOCK) and conv.kernel_size[0] == conv.kernel_size[1]
            and conv.kernel_size[0] % 2 == 1 and conv.padding == (conv.kernel_size[0] // 2,) * 2
            and conv.dilation == (1, 1) and conv.groups == 1 and conv.bias is None
            and conv.padding_mode == "zeros")


def _first_tap(kernel: int) -> int:
    """The offset of the grown kernel's first tap: grown by a zero tap in front or behind, so it
    starts on a block's first pixel (an even offset)."""
    half = kernel // 2
    return -(half + 1) if half % 2 else -half


def block_padding(kernel: int) -> tuple[int, int]:
    """Zero blocks before and after each side for a stem of ``kernel`` (odd)."""
    first = _first_tap(kernel)
    return -first // BLOCK, (first + kernel) // BLOCK


def block_conv(conv: nn.Conv2d) -> nn.Conv2d:
    """The stride-1 convolution on ``pixel_unshuffle(x, 2)`` (padded by :func:`block_padding`)
    that equals ``conv`` on ``x``."""
    if not fits(conv):
        raise ValueError(f"not a stride-2 odd-kernel stem convolution: {conv}")
    w = conv.weight.detach()
    o, c, k, _ = w.shape
    grown = torch.zeros(o, c, k + 1, k + 1, dtype=w.dtype)
    at = -(k // 2) - _first_tap(k)            # 1: the zero tap is in front, 0: behind
    grown[:, :, at:at + k, at:at + k] = w
    side = (k + 1) // BLOCK
    blocks = grown.reshape(o, c, side, BLOCK, side, BLOCK).permute(0, 1, 3, 5, 2, 4)
    out = nn.Conv2d(c * BLOCK * BLOCK, o, side, 1, 0, bias=False)
    out.weight.data.copy_(blocks.reshape(o, c * BLOCK * BLOCK, side, side))
    return out


class SpaceToDepthInput(nn.Module):
    """uint8-valued BGR NCHW frame (as float) -> the stem's padded block input: shrunk by
    ``shrink`` (an integer box average), put through ``normalise`` (a fixed 1x1 convolution: the
    channel flip and ``(x / 255 - mean) / std``), laid out as ``pixel_unshuffle(., 2)`` and
    zero-padded for a stem of ``kernel``. One fixed convolution and a pad."""

    def __init__(self, normalise: nn.Conv2d, shrink: int, kernel: int) -> None:
        super().__init__()
        if int(shrink) != shrink or shrink < 1:
            raise ValueError(f"shrink must be a positive integer, got {shrink}")
        if normalise.kernel_size != (1, 1) or normalise.in_channels != 3 or normalise.out_channels != 3:
            raise ValueError(f"normalise must be a 1x1 convolution from 3 channels to 3, got {normalise}")
        side = BLOCK * shrink
        gain = normalise.weight.detach()[:, :, 0, 0] / (shrink * shrink)      # [out channel, in channel]
        w = torch.zeros(3 * BLOCK * BLOCK, 3, side, side)
        b = torch.zeros(3 * BLOCK * BLOCK)
        for c in range(3):
            for dy in range(BLOCK):
                for dx in range(BLOCK):
                    ch = (c * BLOCK + dy) * BLOCK + dx       # pixel_unshuffle's channel order
                    w[ch, :, dy * shrink:(dy + 1) * shrink, dx * shrink:(dx + 1) * shrink] = gain[c][:, None, None]
                    b[ch] = cast(Tensor, normalise.bias).detach()[c]
        self.conv = nn.Conv2d(3, 3 * BLOCK * BLOCK, side, side)
        self.conv.weight.data.copy_(w)
        cast(Tensor, self.conv.bias).data.copy_(b)
        self.requires_grad_(False)
        self.shrink = int(shrink)
        before, after = block_padding(kernel)
        self.pad = (before, after, before, after)

    def forward(self, frame: Tensor) -> Tensor:
        return F.pad(self.conv(frame), self.pad)
