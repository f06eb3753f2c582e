"""The fused ONNX model: D and B in one graph, normalisation inside, the runtime's contract.

Input ``frame``: uint8 ``[1, H, W, 3]``, BGR as OpenCV decodes it, already at the model's size.
Outputs ``blindspot``: float32 ``[1, 1, H, W]`` probabilities; ``depth``: float32 ``[1, 1, H, W]``
metres. ``metadata_props`` carries the sealed model card (``bsn_edge.card``), all the runtime needs.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import onnx
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from bsn_edge.card import ModelCard
from bsn_edge.data.dataset import IMAGENET_MEAN, IMAGENET_STD
from bsn_edge.export.prune import Pruned, prune
from bsn_edge.export.seal import seal, set_metadata
from bsn_edge.export.space_to_depth import SpaceToDepthInput, block_conv, fits
from bsn_edge.export.upsample import ShuffleUpsample, with_shuffle_upsampling
from bsn_edge.modelfile.read import session

OPSET = 17
PARITY_ATOL = 1e-3      # fp32 onnxruntime vs torch, on probabilities
DEPTH_RTOL = 1e-3       # and on depth, relative


NORMALISE = "normalise"   # the module (and ONNX node scope) turning the frame into network input


def normalisation(mean: np.ndarray, std: np.ndarray) -> nn.Conv2d:
    """A fixed 1x1 convolution: BGR 0..255 in, RGB ``(x / 255 - mean) / std`` out. One op for
    the channel flip, scale and shift, which onnxruntime runs in its blocked layout."""
    conv = nn.Conv2d(3, 3, 1)
    w = torch.zeros(3, 3, 1, 1)
    for rgb in range(3):
        w[rgb, 2 - rgb] = 1.0 / (255.0 * float(std[rgb]))
    conv.weight.data.copy_(w)
    cast(Tensor, conv.bias).data.copy_(torch.from_numpy(-mean / std))
    conv.requires_grad_(False)
    return conv


class FusedModel(nn.Module):
    """uint8 BGR NHWC frame -> (blind-spot probabilities, depth in metres).

    The same numbers as the torch model (to float rounding), in the ops a CPU runs fastest:
    bilinear upsampling as convolution + depth-to-space (``export.upsample``), and the
    normalisation as one fixed 1x1 convolution. A model with ``predict_coarse`` (the shared
    encoder's) is brought from its decoders' stride to the frame's size in one upsampling per head
    and, built for a frame ``size`` that divides evenly, reads the frame in 2 x 2 blocks: its
    ``frame_encoder``'s stem on a space-to-depth input (``export.space_to_depth``) made by one
    fixed convolution of the frame. Such a model takes frames of that size only.
    """

    def __init__(self, model: nn.Module, size: tuple[int, int] | None = None) -> None:
        super().__init__()
        # Any: the model families answer through methods of their own (predict_coarse, forward_scaled)
        self.model: Any = with_shuffle_upsampling(model.eval())
        setattr(self, NORMALISE, normalisation(IMAGENET_MEAN, IMAGENET_STD))
        scale = getattr(model, "input_scale", 1.0)
        up = getattr(model, "upsample", None)
        self.to_frame: ShuffleUpsample | None = None
        if hasattr(model, "predict_coarse") and (up is not None or scale == 1.0):
            self.to_frame = ShuffleUpsample(cast(int, model.coarse_stride), *((up.factor,) if up is not None else ()))
        self.size: tuple[int, ...] | None = tuple(size) if size is not None else None
        encoder: Any = getattr(self.model, "frame_encoder", None)
        self.blocks = (self.size is not None and self.to_frame is not None and encoder is not None
                       and fits(encoder.stem[0]) and all(s % self.to_frame.factor == 0 for s in self.size))
        if self.blocks:
            stem = encoder.stem[0]
            setattr(self, NORMALISE, SpaceToDepthInput(getattr(self, NORMALISE), round(1.0 / scale),
                                                       stem.kernel_size[0]))
            encoder.stem[0] = block_conv(stem)

    def forward(self, frame: Tensor) -> tuple[Tensor, Tensor]:
        x = frame.permute(0, 3, 1, 2).to(torch.float32)
        size = tuple(x.shape[2:])
        if self.blocks and self.size is not None and size != self.size:
            raise ValueError(f"this fused model reads {self.size[0]}x{self.size[1]} frames, "
                             f"got {size[0]}x{size[1]}")
        scale = getattr(self.model, "input_scale", 1.0)
        if scale != 1.0 and not self.blocks:
            # bilinear resizing commutes with the per-channel affine normalisation and the channel
            # flip, so shrink first and normalise a quarter of the pixels
            x = F.interpolate(x, scale_factor=scale, mode="bilinear", align_corners=False, antialias=False)
        x = getattr(self, NORMALISE)(x)
        if self.to_frame is not None and all(int(s) % self.to_frame.factor == 0 for s in size):
            logits, log_depth, _ = self.model.predict_coarse(x)
            return torch.sigmoid(self.to_frame(logits)), self.to_frame(log_depth).exp()
        logits, depth, _ = self.model.forward_scaled(x, size)
        return torch.sigmoid(logits), depth


@dataclass(frozen=True)
class Exported:
    """A sealed fused export: its card, and what pruning removed (None when not asked)."""

    card: ModelCard
    pruned: Pruned | None


def export_fused(model: nn.Module, out: str | Path, card: ModelCard, prune_dead: bool = True) -> Exported:
    """Export ``model`` (a BlindSpotNet) fused at ``card.input_size`` to ``out``, sealed with ``card``;
    with ``prune_dead`` the convolution channels nothing reads are first taken out of the graph
    (``export.prune``: the same outputs, fewer multiply-accumulates)."""
    out = Path(out)
    h, w = card.input_size
    fused = FusedModel(model.eval(), (h, w)).eval()
    dummy = torch.zeros(1, h, w, 3, dtype=torch.uint8)
    tmp = out.with_suffix(".tmp.onnx")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            torch.onnx.export(fused, (dummy,), str(tmp), input_names=["frame"],
                              output_names=["blindspot", "depth"], opset_version=OPSET, dynamo=False,
                              do_constant_folding=True)
        m = onnx.load(str(tmp))
        pruned = prune(m) if prune_dead else None
        set_metadata(m, card)
        onnx.checker.check_model(m)
        onnx.save(m, str(tmp))
        return Exported(seal(tmp, card, out), pruned)
    finally:
        tmp.unlink(missing_ok=True)


def to_onnx(model: nn.Module, out: str | Path, card: ModelCard) -> ModelCard:
    """Export ``model`` (a BlindSpotNet) fused at ``card.input_size``, unpruned, sealed with ``card``;
    returns the sealed card."""
    return export_fused(model, out, card, prune_dead=False).card


def check_parity(model: nn.Module, path: str | Path, frames: list[np.ndarray]) -> dict[str, float]:
    """Largest differences between onnxruntime and torch on ``frames`` (uint8 BGR HxWx3); raises
    ``ValueError`` beyond the stated tolerances."""
    sess = session(path)
    fused = FusedModel(model.eval()).eval()
    worst_p = worst_d = 0.0
    for f in frames:
        with torch.no_grad():
            p_t, d_t = (t.numpy() for t in fused(torch.from_numpy(f[None])))
        p_o, d_o = sess.run(None, {"frame": f[None]})
        worst_p = max(worst_p, float(np.abs(p_o - p_t).max()))
        worst_d = max(worst_d, float((np.abs(d_o - d_t) / np.maximum(d_t, 1e-3)).max()))
    if worst_p > PARITY_ATOL or worst_d > DEPTH_RTOL:
        raise ValueError(f"{path}: onnxruntime disagrees with torch (probability {worst_p:.2e} > "
                         f"{PARITY_ATOL} or depth {worst_d:.2e} > {DEPTH_RTOL} relative)")
    return {"max_abs_prob": worst_p, "max_rel_depth": worst_d}
