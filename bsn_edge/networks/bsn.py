"""BlindSpotNet: a depth estimator D, then a blind-spot estimator B on RGB + D's depth."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from bsn_edge.networks.deeplab import EncoderDecoder
from bsn_edge.networks.resnet import ResNetEncoder
from bsn_edge.networks.upsample import Upsample

MIN_DEPTH_M, MAX_DEPTH_M = 0.5, 120.0   # D's output range; sky is taught as the far end
LOG_MIN_DEPTH, LOG_MAX_DEPTH = math.log(MIN_DEPTH_M), math.log(MAX_DEPTH_M)
DEPTH_FEATURE_M = 10.0                  # B sees 10 / (depth + 10): bounded, fine near, coarse far
ORACLE_DEPTH_NOTE = "its B reads ground-truth depth, which no camera has (oracle_depth, a research arm)"


def depth_feature(depth: Tensor) -> Tensor:
    """What B sees of the depth: ``s / (depth + s)`` in (0, 1], resolving near range finely."""
    return DEPTH_FEATURE_M / (depth + DEPTH_FEATURE_M)


def given_depth_feature(depth: Tensor, size) -> Tensor:
    """``depth_feature`` of a given depth map (metres, 0 where there is none: sky, which D is
    taught as its far end) at ``size``, area-averaged where ``size`` is smaller."""
    d = torch.where(depth > 0, depth, torch.full_like(depth, MAX_DEPTH_M)).clamp(MIN_DEPTH_M, MAX_DEPTH_M)
    f = depth_feature(d)
    return f if tuple(f.shape[2:]) == tuple(size) else F.interpolate(f, size=size, mode="area")


def metres_from_log(log_depth: Tensor) -> Tensor:
    """D's log-depth as metres within its output range."""
    return log_depth.clamp(LOG_MIN_DEPTH, LOG_MAX_DEPTH).exp()


class DepthNet(nn.Module):
    """D: monocular metric depth. Predicts log-depth, returned as metres in [0.5, 120]."""

    def __init__(self, encoder_depth: int = 18, width: int = 64, separable: bool = True,
                 output_stride: int = 16) -> None:
        super().__init__()
        self.net = EncoderDecoder(ResNetEncoder(encoder_depth, 3, output_stride), 1, width, separable)

    def forward(self, x: Tensor) -> Tensor:
        log_d, _ = self.net(x)
        return metres_from_log(log_d)


class BlindSpotNet(nn.Module):
    """D and B in one module: ``forward(rgb) -> (blind-spot logits, depth metres, B's decoder features)``.

    ``rgb`` is normalised float ``[N, 3, H, W]``. B takes RGB plus ``depth_feature`` of D's depth
    (detached: B's loss does not train D) unless ``use_depth`` is off (the paper's BSN-D).
    ``input_scale`` < 1 runs both networks on a smaller copy of the frame and brings the outputs
    back to the frame's size: the cheapest lever on a CPU's frame rate.

    ``oracle_depth`` is a research arm: B reads the ground-truth depth passed as
    ``forward(rgb, depth)`` (metres ``[N, 1, H, W]``, 0 = none) instead of D's, which says how much
    better depth would help B. No camera has that depth, so such a model cannot run in the car.
    """

    def __init__(self, blindspot: nn.Module, depth_net: nn.Module, use_depth: bool = True,
                 input_scale: float = 1.0, oracle_depth: bool = False) -> None:
        super().__init__()
        if not 0.1 <= input_scale <= 1.0:
            raise ValueError(f"input_scale must be in [0.1, 1], got {input_scale}")
        if oracle_depth and not use_depth:
            raise ValueError("oracle_depth gives B ground-truth depth: it needs use_depth")
        self.depth_net = depth_net
        self.blindspot = blindspot
        self.use_depth = use_depth
        self.oracle_depth = oracle_depth
        self.input_scale = input_scale
        factor = 1.0 / input_scale
        # integer factors (0.5 -> 2) upsample through a module an exporter can swap; others resize
        self.upsample = Upsample(round(factor)) if abs(factor - round(factor)) < 1e-6 else None

    def forward(self, rgb: Tensor, depth: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
        size = rgb.shape[2:]
        x = rgb
        if self.input_scale != 1.0:
            x = F.interpolate(rgb, scale_factor=self.input_scale, mode="bilinear", align_corners=False,
                              antialias=False)
        return self.forward_scaled(x, size, depth)

    def seen_depth(self, depth: Tensor, given: Tensor | None) -> Tensor:
        """What B reads of the depth at ``depth``'s size: ``depth_feature`` of D's ``depth``
        (detached), or of the ``given`` ground truth for an ``oracle_depth`` model."""
        if not self.oracle_depth:
            if given is not None:
                raise ValueError("this model's B reads D's depth; only an oracle_depth model takes a given depth")
            return depth_feature(depth.detach())
        if given is None:
            raise ValueError(f"{ORACLE_DEPTH_NOTE}: pass it as model(rgb, depth)")
        return given_depth_feature(given, depth.shape[2:])

    def predict(self, x: Tensor, given: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
        """Blind-spot logits, depth in metres and B's decoder features, at the size of ``x`` (the
        input already resized by ``input_scale``; ``given``: ground-truth depth, any size, for an
        ``oracle_depth`` model). Subclasses with another layout fill this hook;
        :meth:`forward_scaled` owns bringing the outputs back to the frame's size."""
        depth = self.depth_net(x)
        inp = torch.cat([x, self.seen_depth(depth, given)], 1) if self.use_depth else x
        logits, feats = self.blindspot(inp)
        return logits, depth, feats

    def forward_scaled(self, x: Tensor, size, given: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
        """``forward`` for an input already resized by ``input_scale``; outputs at ``size``.

        Depth is resized as log-depth, the quantity D predicts: one interpolation of D's output
        whatever the scale (an exporter composes the steps into one), and within D's range."""
        logits, depth, feats = self.predict(x, given)
        if self.input_scale != 1.0:
            log_depth = depth.log()
            # a constant scale factor, not the input's traced shape: exported graphs stay static,
            # which OpenCV's DNN module needs
            if self.upsample is not None:
                logits, log_depth = self.upsample(logits), self.upsample(log_depth)
            else:
                up = 1.0 / self.input_scale
                logits = F.interpolate(logits, scale_factor=up, mode="bilinear", align_corners=False)
                log_depth = F.interpolate(log_depth, scale_factor=up, mode="bilinear", align_corners=False)
            if tuple(logits.shape[2:]) != tuple(size):   # sizes not divisible by 1 / input_scale
                logits = F.interpolate(logits, size=size, mode="bilinear", align_corners=False)
                log_depth = F.interpolate(log_depth, size=size, mode="bilinear", align_corners=False)
            depth = log_depth.exp()
        return logits, depth, feats
