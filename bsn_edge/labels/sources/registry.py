"""Spec strings -> source objects."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from bsn_edge.labels.sources.base import ClipData, DepthSource, SegSource
from bsn_edge.labels.sources.files import FilesDepth, FilesSeg, load_poses

if TYPE_CHECKING:
    from bsn_edge.labels.config import LabelConfig

DEPTH_KINDS = ("files", "onnx:MODEL")
SEG_KINDS = ("files", "onnx:MODEL")
POSE_KINDS = ("files", "vo", "TRAJ.txt")


def make_depth(spec: str, clip: ClipData, poses: np.ndarray, cfg: LabelConfig) -> DepthSource:
    if spec == "files":
        return FilesDepth(clip)
    if spec.startswith("onnx:"):
        from bsn_edge.labels.sources.onnx_depth import OnnxDepth
        return OnnxDepth.for_clip(spec[5:], clip, poses, cfg)
    raise ValueError(f"unknown depth source {spec!r}; valid: {', '.join(DEPTH_KINDS)}")


def make_seg(spec: str, clip: ClipData) -> SegSource:
    if spec == "files":
        return FilesSeg(clip)
    if spec.startswith("onnx:"):
        from bsn_edge.labels.sources.onnx_seg import OnnxSeg
        return OnnxSeg(spec[5:], clip)
    raise ValueError(f"unknown segmentation source {spec!r}; valid: {', '.join(SEG_KINDS)}")


def make_poses(spec: str, clip: ClipData) -> tuple[np.ndarray, dict[str, Any]]:
    if spec == "vo":
        from bsn_edge.labels.vo import run_vo
        poses, info = run_vo(clip)
        return poses, {"kind": "vo", **info}
    return load_poses(clip, spec), {"kind": "files" if spec == "files" else "trajectory", "path": spec}
