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

from bsn_edge.networks.bsn import LOG_MAX_DEPTH, LOG_MIN_DEPTH, BlindSpotNet
from bsn_edge.networks.deeplab import DeepLabV3PlusDecoder, SegmentationHead, aspp_rates, conv_bn_relu
from bsn_edge.networks.encoder_base import Encoder
from bsn_edge.networks.resnet import ResNetEncoder

DEPTH_CHANNELS = 16     # B's learnt view of the depth feature, so int8 concatenation keeps its scale


class SharedDepth(nn.Module):
    """D of the shared model: the encoder both networks read, a light decoder and a log-depth head.

    ``forward(x)`` is depth in metres at the size of ``x``, as :class:`~bsn_edge.networks.DepthNet`.
    Log-depth is held to D's range at the decoder's stride and then interpolated, which keeps it
    in range, so every resizing after that is linear in log-depth."""

    def __init__(self, encoder: Encoder, width: int, separable: bool = True) -> None:
        super().__init__()
        self.encoder = encoder
        self.decoder = DeepLabV3PlusDecoder(encoder.out_channels, width, separable=separable,
                                            rates=aspp_rates(encoder.strides[-1]))
        self.head = SegmentationHead(self.decoder.out_channels, 1, encoder.strides[0])

    def coarse(self, feats: list[Tensor]) -> Tensor:
        """Log-depth at the decoder's stride (the encoder's first), within D's range."""
        return self.head.conv(self.decoder(feats)).clamp(LOG_MIN_DEPTH, LOG_MAX_DEPTH)

    def forward(self, x: Tensor) -> Tensor:
        return self.head.up(self.coarse(self.encoder(x))).exp()


class DepthAwareDecoder(nn.Module):
    """B of the shared model: a DeepLabV3+ decoder on the shared encoder's features, with D's depth
    (``depth_feature``, through a small learnt convolution) concatenated to the shallowest features
    and, pooled, to the deepest. Without depth (``use_depth=False``, the paper's BSN-D) it is a
    plain decoder on the shared features. ``forward(feats, depth) -> (logits, decoder features)``;
    :meth:`coarse` gives the logits at the decoder's stride."""

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
        logits, x = self.coarse(feats, depth)
        return self.head.up(logits), x

    def coarse(self, feats: list[Tensor], depth: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Logits at the decoder's stride (before the head's upsampling) and the decoder's features."""
        if self.depth_in is not None:
            if depth is None:
                raise ValueError("this decoder was built to read depth; none given")
            d = self.depth_in(depth)
            feats = [torch.cat([feats[0], d], 1), *feats[1:-1],
                     torch.cat([feats[-1], F.avg_pool2d(d, self.pool)], 1)]
        x = self.decoder(feats)
        return self.head.conv(x), x


class SharedEncoderBSN(BlindSpotNet):
    """D and B on one ResNet encoder; the same interface as :class:`BlindSpotNet`.

    ``depth_net`` owns the encoder, so freezing it (``bsn-adapt``) leaves B's decoder to learn."""

    depth_net: SharedDepth
    blindspot: DepthAwareDecoder

    def __init__(self, encoder_depth: int = 18, output_stride: int = 32, decoder_width: int = 64,
                 depth_width: int = 32, separable: bool = True, use_depth: bool = True,
                 input_scale: float = 1.0, oracle_depth: bool = False, encoder: Encoder | None = None) -> None:
        # ``encoder``: any module publishing out_channels and strides (default: a ResNet of encoder_depth)
        encoder = encoder if encoder is not None else ResNetEncoder(encoder_depth, 3, output_stride)
        d = SharedDepth(encoder, depth_width)       # D's decoder is separable in both layouts
        b = DepthAwareDecoder(encoder.out_channels, encoder.strides, decoder_width, separable, use_depth)
        super().__init__(b, d, use_depth, input_scale, oracle_depth)

    @property
    def frame_encoder(self) -> nn.Module:
        """The one module that reads the network's input (B reads only its features)."""
        return self.depth_net.encoder

    @property
    def coarse_stride(self) -> int:
        """How much smaller than the network's input :meth:`predict_coarse`'s outputs are."""
        return self.depth_net.encoder.strides[0]

    def predict_coarse(self, x: Tensor, given: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
        """Blind-spot logits and log-depth at :attr:`coarse_stride`, and B's decoder features:
        :meth:`predict` before its bilinear upsampling, which an exporter can fuse with the frame's."""
        feats = self.depth_net.encoder(x)
        log_coarse = self.depth_net.coarse(feats)
        seen = self.seen_depth(log_coarse.exp(), given) if self.use_depth else None
        logits, b_feats = self.blindspot.coarse(feats, seen)
        return logits, log_coarse, b_feats

    def predict(self, x: Tensor, given: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
        logits, log_coarse, b_feats = self.predict_coarse(x, given)
        return self.blindspot.head.up(logits), self.depth_net.head.up(log_coarse).exp(), b_feats
