"""ASPP and the DeepLabV3+ decoder, built from an encoder's published channels."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from bsn_edge.networks.encoder_base import Encoder
from bsn_edge.networks.upsample import Upsample


def conv_bn_relu(cin: int, cout: int, k: int = 3, dilation: int = 1,
                 separable: bool = False) -> nn.Sequential:
    """A k x k convolution (optionally depthwise-separable), batch norm, ReLU."""
    pad = dilation * (k // 2)
    if separable and k > 1:
        return nn.Sequential(
            nn.Conv2d(cin, cin, k, 1, pad, dilation, groups=cin, bias=False),
            nn.Conv2d(cin, cout, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))
    return nn.Sequential(nn.Conv2d(cin, cout, k, 1, pad, dilation, bias=False), nn.BatchNorm2d(cout),
                         nn.ReLU(inplace=True))


def aspp_rates(output_stride: int) -> tuple[int, int, int]:
    """ASPP's dilation rates for an encoder's output stride: DeepLabV3+'s are set for 16; at 32 the
    same field of view needs half the rates."""
    return (6, 12, 18) if output_stride == 16 else (3, 6, 9)


class ASPP(nn.Module):
    """Atrous spatial pyramid pooling: a 1x1 branch, one dilated 3x3 per rate, image pooling."""

    def __init__(self, cin: int, cout: int, rates: tuple[int, ...] = (6, 12, 18), separable: bool = False,
                 dropout: float = 0.1) -> None:
        super().__init__()
        self.branches = nn.ModuleList(
            [conv_bn_relu(cin, cout, 1)] + [conv_bn_relu(cin, cout, 3, r, separable) for r in rates])
        self.pool = nn.Sequential(nn.AdaptiveAvgPool2d(1), nn.Conv2d(cin, cout, 1, bias=False),
                                  nn.ReLU(inplace=True))
        self.project = nn.Sequential(conv_bn_relu(cout * (len(rates) + 2), cout, 1), nn.Dropout(dropout))

    def forward(self, x: Tensor) -> Tensor:
        outs = [b(x) for b in self.branches]
        outs.append(self.pool(x).expand(-1, -1, x.shape[2], x.shape[3]))
        return self.project(torch.cat(outs, 1))


class DeepLabV3PlusDecoder(nn.Module):
    """ASPP on the deepest features, upsampled to stride 4 and fused with the shallowest.

    ``width`` sets the decoder's channels: 256 is the paper's DeepLabV3+; a light decoder
    (e.g. 64, separable) is what decides a CPU's frame rate. ``out_channels == width``.
    """

    def __init__(self, encoder_channels: tuple[int, ...], width: int = 256, low_channels: int = 48,
                 separable: bool = False, rates: tuple[int, ...] = (6, 12, 18)) -> None:
        super().__init__()
        if width < 8:
            raise ValueError(f"decoder width must be >= 8, got {width}")
        self.aspp = ASPP(encoder_channels[-1], width, rates, separable)
        self.low = conv_bn_relu(encoder_channels[0], low_channels, 1)
        self.fuse = nn.Sequential(conv_bn_relu(width + low_channels, width, 3, separable=separable),
                                  conv_bn_relu(width, width, 3, separable=separable))
        self.out_channels = width

    def forward(self, feats: list[Tensor]) -> Tensor:
        x = self.aspp(feats[-1])
        low = self.low(feats[0])
        x = F.interpolate(x, size=low.shape[2:], mode="bilinear", align_corners=False)
        return self.fuse(torch.cat([x, low], 1))


class SegmentationHead(nn.Module):
    """1x1 convolution to ``classes`` and bilinear upsampling by ``scale``."""

    def __init__(self, cin: int, classes: int, scale: int = 4) -> None:
        super().__init__()
        self.conv = nn.Conv2d(cin, classes, 1)
        self.up = Upsample(scale)

    def forward(self, x: Tensor) -> Tensor:
        return self.up(self.conv(x))


class EncoderDecoder(nn.Module):
    """Encoder -> DeepLabV3+ decoder -> head. ``forward`` returns ``(logits, decoder features)``."""

    def __init__(self, encoder: Encoder, classes: int, width: int = 256, separable: bool = False) -> None:
        super().__init__()
        self.encoder = encoder
        self.decoder = DeepLabV3PlusDecoder(encoder.out_channels, width, separable=separable,
                                            rates=aspp_rates(encoder.strides[-1]))
        self.head = SegmentationHead(self.decoder.out_channels, classes, encoder.strides[0])

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor]:
        feats = self.decoder(self.encoder(x))
        return self.head(feats), feats
