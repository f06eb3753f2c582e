"""BlindSpotNet with one encoder for D and B: about half the multiply-accumulates of two.

The two-network model runs a ResNet encoder for D on RGB and another for B on RGB + depth; the
encoders are nearly all of its cost. Here one encoder reads the frame, D's decoder turns its
features into depth, and B's decoder reads the same features with D's depth beside them (at the
decoder's shallow and deep inputs), so B still estimates from RGB and depth. D's depth reaches B
detached, as in the two-network model; the shared encoder is trained by both losses.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from bsn_edge.models.bsn import BlindSpotNet, depth_feature, metres_from_log
from bsn_edge.models.deeplab import DeepLabV3PlusDecoder, SegmentationHead, aspp_rates, conv_bn_relu
from bsn_edge.models.resnet import ResNetEncoder

DEPTH_CHANNELS = 16     # B's learnt view of the depth feature, so int8 concatenation keeps its scale


class SharedDepth(nn.Module):
    """D of the shared model: the encoder both networks read, a light decoder and a log-depth head.

    ``forward(x)`` is depth in metres at the size of ``x``, as :class:`~bsn_edge.models.DepthNet`."""

    def __init__(self, encoder: ResNetEncoder, width: int, separable: bool = True) -> None:
        super().__init__()
        self.encoder = encoder
        self.decoder = DeepLabV3PlusDecoder(encoder.out_channels, width, separable=separable,
                                            rates=aspp_rates(encoder.strides[-1]))
        self.head = SegmentationHead(self.decoder.out_channels, 1, encoder.strides[0])

    def coarse(self, feats: list[Tensor]) -> Tensor:
        """Log-depth at the decoder's stride (the encoder's first), unclamped."""
        return self.head.conv(self.decoder(feats))

    def forward(self, x: Tensor) -> Tensor:
        return metres_from_log(self.head.up(self.coarse(self.encoder(x))))


class DepthAwareDecoder(nn.Module):
    """B of the shared model: a DeepLabV3+ decoder on the shared encoder's features, with D's depth
    (``depth_feature``, through a small learnt convolution) concatenated to the shallowest features
    and, pooled, to the deepest. Without depth (``use_depth=False``, the paper's BSN-D) it is a
    plain decoder on the shared features. ``forward(feats, depth) -> (logits, decoder features)``."""

    def __init__(self, encoder_channels: tuple[int, ...], strides: tuple[int, ...], width: int,
                 separable: bool = True, use_depth: bool = True) -> None:
        super().__init__()
        extra = DEPTH_CHANNELS if use_depth else 0
        channels = (encoder_channels[0] + extra, *encoder_channels[1:-1], encoder_channels[-1] + extra)
        self.depth_in = conv_bn_relu(1, DEPTH_CHANNELS, 3) if use_depth else None
        self.pool = strides[-1] // strides[0]
        self.decoder = DeepLabV3PlusDecoder(channels, width, separable=separable, rates=aspp_rates(strides[-1]))
        self.head = SegmentationHead(self.decoder.out_channels, 1, strides[0])

    def forward(self, feats: list[Tensor], depth: Tensor | None = None) -> tuple[Tensor, Tensor]:
        if self.depth_in is not None:
            if depth is None:
                raise ValueError("this decoder was built to read depth; none given")
            d = self.depth_in(depth)
            feats = [torch.cat([feats[0], d], 1), *feats[1:-1],
                     torch.cat([feats[-1], F.avg_pool2d(d, self.pool)], 1)]
        x = self.decoder(feats)
        return self.head(x), x


class SharedEncoderBSN(BlindSpotNet):
    """D and B on one ResNet encoder; the same interface as :class:`BlindSpotNet`.

    ``depth_net`` owns the encoder, so freezing it (``bsn-adapt``) leaves B's decoder to learn."""

    def __init__(self, encoder_depth: int = 18, output_stride: int = 32, decoder_width: int = 64,
                 depth_width: int = 32, separable: bool = True, use_depth: bool = True,
                 input_scale: float = 1.0) -> None:
        encoder = ResNetEncoder(encoder_depth, 3, output_stride)
        d = SharedDepth(encoder, depth_width)       # D's decoder is separable in both layouts
        b = DepthAwareDecoder(encoder.out_channels, encoder.strides, decoder_width, separable, use_depth)
        super().__init__(b, d, use_depth, input_scale)

    def predict(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        feats = self.depth_net.encoder(x)
        log_coarse = self.depth_net.coarse(feats)
        depth = metres_from_log(self.depth_net.head.up(log_coarse))
        seen = depth_feature(metres_from_log(log_coarse).detach()) if self.use_depth else None
        logits, b_feats = self.blindspot(feats, seen)
        return logits, depth, b_feats
