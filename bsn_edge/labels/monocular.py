"""Poses and metric depth for a clip that has neither: relative depth + segmentation + video.

1. Monocular VO from essential matrices gives a trajectory whose scale drifts.
2. Landmarks triangulated with it align the relative depth (least squares) into those units.
3. Each label-rate frame is brought to metres on its own: a plane fitted to its traversable
   pixels must lie the camera's height below it. This also undoes the drift of step 1.
4. VO again, now with PnP against the metric depth, over the label-rate frames: metric poses.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.labels.sources.base import ClipData, DepthSource, SegSource
from bsn_edge.labels.vo import metric_scale_from_ground, visual_odometry
from bsn_edge.sequence.frames import read_gray


class PerFrameScaled(DepthSource):
    """A depth source multiplied by one factor per frame."""

    name = "ground-scaled"

    def __init__(self, base: DepthSource, factors: dict[int, float]) -> None:
        self.base, self.factors = base, factors

    def __call__(self, i: int) -> np.ndarray:
        return self.base(i) * np.float32(self.factors[i])

    def describe(self) -> dict[str, Any]:
        f = np.array(list(self.factors.values()))
        return {**self.base.describe(), "metres_from": "camera height over the fitted ground plane",
                "factor_median": float(np.median(f)), "factor_spread": float(f.std() / np.median(f))}


def seed_poses(clip: ClipData) -> tuple[np.ndarray, dict[str, Any]]:
    """Step 1: monocular VO over every frame (units of the first step)."""
    frames = [read_gray(clip.seq, i) for i in range(clip.frames)]
    poses, info = visual_odometry(frames, clip.meta.intrinsics.K)
    return poses, {"seed": info}


def metric_depth_and_poses(clip: ClipData, depth: DepthSource, seg: SegSource, idx: np.ndarray,
                           camera_height: float) -> tuple[DepthSource, np.ndarray, dict[str, Any]]:
    """Steps 3 and 4, given depth aligned to the seed poses (step 2)."""
    K = clip.meta.intrinsics.K
    factors: dict[int, float] = {}
    failed = 0
    for i in (int(j) for j in idx):
        try:
            factors[i] = metric_scale_from_ground([depth(i)], [sm.is_traversable(seg(i))], K, camera_height)
        except ValueError:
            failed += 1
    if not factors:
        raise ValueError("no frame shows enough road to find metres from the camera height")
    med = float(np.median(list(factors.values())))
    for i in (int(j) for j in idx):
        factors.setdefault(i, med)
    metric = PerFrameScaled(depth, factors)
    frames = [read_gray(clip.seq, int(i)) for i in idx]
    poses_idx, info = visual_odometry(frames, K, depth=lambda k: metric(int(idx[k])))
    poses = fill_poses(poses_idx, idx, clip.frames)
    return metric, poses, {"final": info, "frames_without_ground": failed, "camera_height": camera_height,
                           "poses_between_label_frames": "interpolated"}


def fill_poses(poses_idx: np.ndarray, idx: np.ndarray, n: int) -> np.ndarray:
    """Poses of every frame from those of the label-rate frames (translation interpolated,
    rotation of the nearest); only label-rate frames are used for labels."""
    out = np.empty((n, 4, 4))
    t = np.stack([np.interp(np.arange(n), idx, poses_idx[:, k, 3]) for k in range(3)], axis=1)
    nearest = np.clip(np.searchsorted(idx, np.arange(n)), 0, len(idx) - 1)
    prev = np.clip(nearest - 1, 0, len(idx) - 1)
    nearest = np.where(np.abs(idx[prev] - np.arange(n)) < np.abs(idx[nearest] - np.arange(n)), prev, nearest)
    out[:] = poses_idx[nearest]
    out[:, :3, 3] = t
    return out
