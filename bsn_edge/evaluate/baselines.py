"""The paper's baselines, computed on the same frames as BlindSpotNet.

- Traversable: road or sidewalk hidden behind objects, in the spirit of Watson et al.'s hidden
  footprints: a ray that meets an object before the ground plane (fitted to D's depth on the
  teacher's traversable pixels) hides ground there; it counts when that ground lies within
  range and in a lateral band where visible road or sidewalk exists.
- Detection-2D: vehicle, pedestrian and cyclist pixels of the teacher's segmentation.
- Detection-3D: the far faces of the synthetic world's 3D boxes, projected, intersected with
  Detection-2D (synthetic clips only: it needs ``boxes/``).
"""

from __future__ import annotations

import cv2
import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.camera import Intrinsics

RANGE_M = 50.0
LATERAL_BIN_M = 1.0
NEAR = 0.1


def detection_2d(sem: np.ndarray) -> np.ndarray:
    return np.isin(sem, sm.ROAD_USERS)


def _ground_plane(depth: np.ndarray, trav: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Unit normal n and offset h with n . X = h for ground points X (camera frame)."""
    sel = trav & (depth > 0) & (depth < 30)
    if sel.sum() < 50:
        return None
    v, u = np.nonzero(sel)
    z = depth[sel]
    P = ((np.linalg.inv(K) @ np.vstack([u, v, np.ones(len(u))])) * z).T
    keep = np.ones(len(P), bool)
    for _ in range(2):
        a, *_ = np.linalg.lstsq(P[keep], np.ones(keep.sum()), rcond=None)
        r = np.abs(P @ a - 1)
        keep = r < max(3 * np.median(r[keep]), 1e-6)
    n = np.linalg.norm(a)
    return a / n, float(1.0 / n)


def traversable_hidden(sem: np.ndarray, depth: np.ndarray, intr: Intrinsics) -> np.ndarray:
    K = intr.K
    trav = sm.is_traversable(sem)
    obj = ~trav & (sem != sm.SKY)
    plane = _ground_plane(depth, trav, K)
    if plane is None:
        return np.zeros_like(obj)
    n, h = plane
    rays = intr.rays().astype(np.float64)
    denom = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(denom > 1e-6, h / denom, np.inf)
        gx = rays[..., 0] * t
    gz = t
    hidden = obj & np.isfinite(t) & (t > depth + 0.5) & (np.hypot(gx, gz) <= RANGE_M)
    vis = trav & (depth > 0)
    bins = np.unique(np.floor(rays[..., 0][vis] * depth[vis] / LATERAL_BIN_M).astype(int))
    lanes = set(bins.tolist()) | {b + 1 for b in bins.tolist()} | {b - 1 for b in bins.tolist()}
    hb = np.floor(np.where(hidden, gx, 0) / LATERAL_BIN_M).astype(int)
    return hidden & np.isin(hb, list(lanes))


_FACES = ((0, 2, 6, 4), (1, 3, 7, 5), (0, 1, 5, 4), (2, 3, 7, 6))  # x-min, x-max, y-min, y-max sides


def detection_3d(boxes: np.ndarray, T_wc: np.ndarray, intr: Intrinsics, det2d: np.ndarray) -> np.ndarray:
    """Far (camera-facing-away) vertical faces of vehicle and person boxes, projected, AND Detection-2D.

    ``boxes`` rows: trainId, xmin, ymin, zmin, xmax, ymax, zmax, track (world frame, z up).
    """
    mask = np.zeros(det2d.shape, np.uint8)
    C = T_wc[:3, 3]
    R_cw = T_wc[:3, :3].T
    keep = np.isin(boxes[:, 0].astype(int), sm.ROAD_USERS) if len(boxes) else np.zeros(0, bool)
    for b in boxes[keep]:
        lo, hi = b[1:4], b[4:7]
        corners = np.array([[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]]
                            for i in range(8)])
        centre = 0.5 * (lo + hi)
        cam = (corners - C) @ R_cw.T
        if (cam[:, 2] < NEAR).all() or np.linalg.norm(centre[:2] - C[:2]) > RANGE_M + 10:
            continue
        for face in _FACES:
            fc = corners[list(face)].mean(0)
            outward = fc - centre
            outward[2] = 0
            if outward @ (fc - C) <= 0:      # faces the camera: a near face
                continue
            pc = cam[list(face)]
            if (pc[:, 2] < NEAR).any():
                continue
            uv = (pc @ intr.K.T)[:, :2] / pc[:, 2:]
            cv2.fillConvexPoly(mask, np.round(uv).astype(np.int32), 1)
    return (mask > 0) & det2d
