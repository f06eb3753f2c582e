"""A small U-Net, the architecture baseline of the paper's Table 3."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from bsn_edge.networks.deeplab import conv_bn_relu


class UNet(nn.Module):
    """Four levels of two 3x3 convolutions, max-pool down, bilinear up with skips.

    ``forward`` returns ``(logits, decoder features)`` like ``EncoderDecoder``.
    """

    def __init__(self, in_channels: int, classes: int, base: int = 32) -> None:
        super().__init__()
        chans = [base, base * 2, base * 4, base * 8]
        self.down = nn.ModuleList()
        cin = in_channels
        for c in chans:
            self.down.append(nn.Sequential(conv_bn_relu(cin, c), conv_bn_relu(c, c)))
            cin = c
        self.up = nn.ModuleList()
        for c_skip, c in zip(reversed(chans[:-1]), reversed(chans[1:]), strict=True):
            self.up.append(nn.Sequential(conv_bn_relu(c + c_skip, c_skip), conv_bn_relu(c_skip, c_skip)))
        self.head = nn.Conv2d(chans[0], classes, 1)
        self.out_channels = chans[0]

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor]:
        skips = []
        for i, block in enumerate(self.down):
            x = block(x if i == 0 else F.max_pool2d(x, 2))
            skips.append(x)
        for block, skip in zip(self.up, reversed(skips[:-1]), strict=True):
            x = F.interpolate(x, size=skip.shape[2:], mode="bilinear", align_corners=False)
            x = block(torch.cat([x, skip], 1))
        return self.head(x), x
