"""Spec strings -> source objects."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from bsn_edge.labels.sources.base import ClipData, DepthSource, SegSource
from bsn_edge.labels.sources.files import FilesDepth, FilesSeg, load_poses

if TYPE_CHECKING:
    from bsn_edge.labels.config import LabelConfig

DEPTH_KINDS = ("files", "onnx:MODEL", "bsn:MODEL", "rel:DIR[:inverse]", "ground")
SEG_KINDS = ("files", "onnx:MODEL")
POSE_KINDS = ("files", "vo", "TRAJ.txt")


def make_depth(spec: str, clip: ClipData, poses: np.ndarray, cfg: LabelConfig,
               frames: list[int], window: int | None = None, seg: SegSource | None = None) -> DepthSource:
    """The depth source; a model's or relative one (``onnx:``, ``bsn:``, ``rel:``) or the road plane's
    (``ground``, which reads ``seg`` and the clip's mounting) is aligned to the poses on ``frames``
    (the label-rate frames; ``window`` as in ``AlignedDepth``) and may raise ``ClipRejectedError``."""
    if spec == "files":
        return FilesDepth(clip)
    if spec.startswith("onnx:"):
        from bsn_edge.labels.sources.onnx_depth import OnnxDepth
        return OnnxDepth.for_clip(spec[5:], clip, poses, cfg, frames, window)
    if spec.startswith("bsn:"):
        from bsn_edge.labels.sources.bsn_depth import BsnDepth
        return BsnDepth.for_clip(spec[4:], clip, poses, cfg, frames, window)
    if spec.startswith("rel:"):
        from bsn_edge.labels.sources.rel_depth import RelFilesDepth
        return RelFilesDepth.from_spec(spec[4:], clip, poses, cfg.min_corr, frames, window)
    if spec == "ground":
        if seg is None:
            raise ValueError("the ground depth source needs the clip's segmentation")
        from bsn_edge.labels.sources.ground_depth import GroundDepth
        return GroundDepth.for_clip(clip, seg, poses, cfg, frames, window)
    raise ValueError(f"unknown depth source {spec!r}; valid: {', '.join(DEPTH_KINDS)}")


def make_seg(spec: str, clip: ClipData) -> SegSource:
    if spec == "files":
        return FilesSeg(clip)
    if spec.startswith("onnx:"):
        from bsn_edge.labels.sources.onnx_seg import OnnxSeg
        return OnnxSeg(spec[5:], clip)
    raise ValueError(f"unknown segmentation source {spec!r}; valid: {', '.join(SEG_KINDS)}")


def make_poses(spec: str, clip: ClipData, metric_depth: DepthSource | None = None
               ) -> tuple[np.ndarray, dict[str, Any]]:
    """Poses from a file, or from the built-in VO (metric when ``metric_depth`` is given)."""
    if spec == "vo":
        from bsn_edge.labels.vo import visual_odometry
        from bsn_edge.sequence.frames import read_gray
        frames = [read_gray(clip.seq, i) for i in range(clip.frames)]
        poses, info = visual_odometry(frames, clip.meta.intrinsics.K, metric_depth)
        return poses, {"kind": "vo", **info}
    return load_poses(clip, spec), {"kind": "files" if spec == "files" else "trajectory", "path": spec}
