"""The ceiling of T-frame labels: which true blind spots actually become visible within T.

For each true blind-spot pixel of frame t, the hidden ground point (ray meets z = 0) is
projected into frames t+1..t+T; it counts as revealed if some later frame sees traversable
ground at that pixel with the point's depth. No T-frame label can recall more than this.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.labels import LabelConfig, resample
from bsn_edge.sequence import SequenceMeta, read_depth, read_kitti_poses, read_mask
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.images import read_image

TOL_M = 0.5


def revealed_share(seq: Path, cfg: LabelConfig) -> tuple[int, int]:
    """``(revealed, total)`` true blind-spot pixels inside V over the labelled frames of ``seq``."""
    meta = SequenceMeta.read(seq)
    K = meta.intrinsics
    folder = SequenceFolder(seq)
    labels = folder.labels(cfg.name)
    poses = read_kitti_poses(folder.poses_path)
    idx = resample(meta.frames, meta.fps, cfg.rate)
    rays = K.rays()
    cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def frame(i: int):
        if i not in cache:
            sem = read_image(folder.semantic(i), cv2.IMREAD_UNCHANGED)
            cache[i] = (read_depth(folder.depth(i)), sm.is_traversable(sem))
        return cache[i]

    seen_total = total = 0
    for k in range(len(idx) - cfg.horizon_frames):
        i = int(idx[k])
        vis_path = labels.visibility(i)
        if not vis_path.exists():
            continue
        gt = read_mask(folder.bsgt(i)) & read_mask(vis_path)
        if not gt.any():
            continue
        T = poses[i]
        d = rays[gt].astype(np.float64) @ T[:3, :3].T
        pts = T[:3, 3] + (-T[2, 3] / d[:, 2])[:, None] * d
        seen = np.zeros(len(pts), bool)
        for j in range(1, cfg.horizon_frames + 1):
            Tj = poses[int(idx[k + j])]
            pc = (pts - Tj[:3, 3]) @ Tj[:3, :3]
            z = pc[:, 2]
            ok = z > 0.1
            zs = np.where(ok, z, 1.0)
            u = np.rint(K.fx * pc[:, 0] / zs + K.cx).astype(int)
            v = np.rint(K.fy * pc[:, 1] / zs + K.cy).astype(int)
            ok &= (u >= 0) & (u < K.width) & (v >= 0) & (v < K.height)
            o = np.flatnonzero(ok)
            dj, tj = frame(int(idx[k + j]))
            hit = (np.abs(dj[v[o], u[o]] - z[o]) < TOL_M) & tj[v[o], u[o]]
            seen[o[hit]] = True
        for old in [c for c in cache if c < int(idx[k + 1])]:
            del cache[old]
        seen_total += int(seen.sum())
        total += len(pts)
    return seen_total, total
