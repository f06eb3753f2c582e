"""Built-in monocular visual odometry for clips that come without poses.

Frame to frame, corners are tracked with Lucas-Kanade. With a metric depth map of the
earlier frame the motion comes from PnP against the lifted corners (metric, no drift of
scale). Without one, it comes from the essential matrix, and the length of each step is
carried over from the last through corners tracked over three frames (triangulated in
both pairs); the whole trajectory is then in the units of the first step, and
:func:`metric_scale_from_ground` can bring it to metres from the camera's height.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

from bsn_edge.tracks import Matches, detect, track, triangulate

MIN_INLIERS = 20
MAX_STEP_CHANGE = 0.5  # a step more than 50 % longer or shorter than the last is suspect
STILL_PX = 1.0         # matches that moved less than this (median) between frames: the camera stood still


def _rel(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 transform mapping camera-i coordinates to camera-(i+1) coordinates."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, np.ravel(t)
    return T


def _essential(K, p0, p1):
    try:
        E, mask = cv2.findEssentialMat(p0, p1, K, cv2.RANSAC, 0.999, 1.0)
    except cv2.error:      # degenerate matches (all but still): OpenCV's polynomial solver gives up
        return None
    if E is None or E.shape != (3, 3):
        return None
    n, R, t, mask = cv2.recoverPose(E, p0, p1, K, mask=mask)
    if n < MIN_INLIERS:
        return None
    return R, t.ravel() / (np.linalg.norm(t) + 1e-12)


MIN_SCALED = 8        # matches with both a depth and a triangulation that an essential step's length needs


def _essential_scaled(K, p0, p1, depth0):
    """Motion from the essential matrix, its length the median ratio of ``depth0`` to the depths the
    unit step triangulates: each point's depth may be rough (the road plane's, at a thing's ground
    contact), their median is not, where PnP's reprojection test would refuse them all."""
    ess = _essential(K, p0, p1)
    if ess is None:
        return None
    R, t = ess
    z, ok = triangulate(K, np.eye(4), np.linalg.inv(_rel(R, t)), p0, p1)
    u, v = np.rint(p0[:, 0]).astype(int), np.rint(p0[:, 1]).astype(int)
    d = depth0[v, u]
    ok &= (d > 0.5) & (d < 80.0)
    if ok.sum() < MIN_SCALED:
        return None
    return R, t * float(np.median(d[ok] / z[ok]))


def _lift(K, pts, depth):
    u, v = np.rint(pts[:, 0]).astype(int), np.rint(pts[:, 1]).astype(int)
    d = depth[v, u]
    ok = (d > 0.5) & (d < 80.0)
    rays = np.linalg.inv(K) @ np.vstack([pts[ok].T, np.ones(ok.sum())])
    return (rays * d[ok]).T, ok


def _solve_pnp(K, X, x):
    if len(X) < MIN_INLIERS:
        return None
    found, rvec, tvec, inl = cv2.solvePnPRansac(X, x, K, None, reprojectionError=1.5,
                                                iterationsCount=200, confidence=0.999,
                                                flags=cv2.SOLVEPNP_EPNP)
    if not found or inl is None or len(inl) < MIN_INLIERS:
        return None
    inl = inl.ravel()
    rvec, tvec = cv2.solvePnPRefineLM(X[inl], x[inl], K, None, rvec, tvec)
    return cv2.Rodrigues(rvec)[0], tvec.ravel(), inl


def _pnp(K, pts0, pts1, depth0, expected_step: float | None):
    """Motion from corners lifted with depth. RANSAC can lock onto a vehicle moving with the
    camera; a step whose length jumps beyond what a car can do in one frame is solved again
    without that consensus set, and the solution closer to the previous step wins."""
    X, ok = _lift(K, pts0, depth0)
    x = pts1[ok]
    sol = _solve_pnp(K, X, x)
    if sol is None or not expected_step:
        return None if sol is None else sol[:2]
    R, t, inl = sol
    if abs(np.linalg.norm(t) / expected_step - 1.0) <= MAX_STEP_CHANGE:
        return R, t
    rest = np.setdiff1d(np.arange(len(X)), inl)
    alt = _solve_pnp(K, X[rest], x[rest])
    if alt is None:
        return R, t
    better = abs(np.linalg.norm(alt[1]) - expected_step) < abs(np.linalg.norm(t) - expected_step)
    return alt[:2] if better else (R, t)


def visual_odometry(frames: list[np.ndarray], K: np.ndarray,
                    depth: Callable[[int], np.ndarray] | None = None,
                    progress: Callable[[int], None] | None = None,
                    matches: Matches | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """Camera-to-world poses ``[N, 4, 4]`` (first frame at the origin) of grayscale ``frames``.

    With ``depth`` (metric depth of frame i) the poses are metric; without, they are in units of
    the first step's length. ``matches(i, i + 1)`` replaces Lucas-Kanade tracking (frames far apart
    in time, :class:`bsn_edge.tracks.FeatureMatches`); a step whose matches barely move is no motion,
    and a step it cannot solve carries the last one's length; with depth, each step is the essential
    matrix's scaled by it (matched points are too few and their depth too rough for PnP).
    """
    n = len(frames)
    poses = [np.eye(4)]
    solved = "pnp_steps" if matches is None else "depth_scaled_steps"
    stats = {solved: 0, "essential_steps": 0, "carried_steps": 0, "still_steps": 0}
    prev_T = _rel(np.eye(3), np.zeros(3))
    prev_pair: tuple[np.ndarray, np.ndarray] | None = None  # tracks of the last pair (in i-1, in i)
    for i in range(n - 1):
        g0, g1 = frames[i], frames[i + 1]
        if matches is None:
            p0 = detect(g0)
            p1, ok = track(g0, g1, p0)
            p0, p1 = p0[ok], p1[ok]
        else:
            p0, p1 = matches(i, i + 1)
        expected = float(np.linalg.norm(prev_T[:3, 3])) if i else None
        still = matches is not None and len(p0) >= MIN_INLIERS and np.median(np.linalg.norm(p1 - p0, axis=1)) < STILL_PX
        step = None
        if depth is not None and len(p0) >= MIN_INLIERS and not still:
            d0 = depth(i)
            step = _pnp(K, p0, p1, d0, expected) if matches is None else _essential_scaled(K, p0, p1, d0)
        if still:
            T_rel = _rel(np.eye(3), np.zeros(3))
            stats["still_steps"] += 1
        elif step is not None:
            T_rel = _rel(*step)
            stats[solved] += 1
        else:
            ess = _essential(K, p0, p1) if len(p0) >= MIN_INLIERS else None
            if ess is None:
                T_rel = prev_T  # assume the motion carries on
                stats["carried_steps"] += 1
            else:
                R, t = ess
                if matches is not None:
                    # the first step solved sets the unit: steps carried before it moved nothing
                    scale = float(np.linalg.norm(prev_T[:3, 3])) or 1.0
                else:
                    scale = _carry_scale(K, frames, i, prev_pair, prev_T, R, t, p0, p1) if i else 1.0
                T_rel = _rel(R, t * scale)
                stats["essential_steps"] += 1
        poses.append(poses[-1] @ np.linalg.inv(T_rel))
        if not still:      # a stop says nothing of the speed the car moves off at
            prev_T = T_rel
        prev_pair = (frames[i], g1)
        if progress:
            progress(1)
    stats["metric"] = depth is not None and stats[solved] > 0
    return np.stack(poses), stats


def _carry_scale(K, frames, i, prev_pair, prev_T, R, t, p0, p1) -> float:
    """Length of step i -> i+1 in the units of the previous step. Corners of frame i-1 tracked
    forward through i to i+1 are triangulated in both pairs; the median ratio of their depths in
    frame i scales the new step. Tracking both pairs the same way round (forward, the image
    expanding) lets the tracker's bias cancel in the ratio."""
    prev_len = float(np.linalg.norm(prev_T[:3, 3]))
    if prev_pair is None or prev_len == 0:
        return 1.0
    q_prev = detect(frames[i - 1])
    q_cur, ok1 = track(frames[i - 1], frames[i], q_prev)
    q_next, ok2 = track(frames[i], frames[i + 1], q_cur)
    ok = ok1 & ok2
    if ok.sum() < MIN_INLIERS:
        return prev_len
    q_prev, q_cur, q_next = q_prev[ok], q_cur[ok], q_next[ok]
    T_prev_w = np.eye(4)                       # frame i-1 at the origin
    T_cur_w = np.linalg.inv(prev_T)            # frame i
    z_a, ok_a = triangulate(K, T_cur_w, T_prev_w, q_cur, q_prev)      # depths in frame i, old scale
    T_next = np.linalg.inv(_rel(R, t))         # frame i+1 seen from frame i, unit step
    z_b, ok_b = triangulate(K, np.eye(4), T_next, q_cur, q_next)
    good = ok_a & ok_b
    if good.sum() < 8:
        return prev_len
    return float(np.median(z_a[good] / z_b[good]))


def metric_scale_from_ground(depths: list[np.ndarray], traversable: list[np.ndarray], K: np.ndarray,
                             camera_height: float) -> float:
    """Factor that turns depth in arbitrary units into metres, from a plane fitted to the
    traversable pixels (nearest 40 % of them) and the camera's known height above it."""
    heights = []
    Kinv = np.linalg.inv(K)
    for d, m in zip(depths, traversable, strict=True):
        sel = m & (d > 0)
        if sel.sum() < 200:
            continue
        v, u = np.nonzero(sel)
        z = d[sel]
        near = z <= np.quantile(z, 0.4)
        P = ((Kinv @ np.vstack([u[near], v[near], np.ones(near.sum())])) * z[near]).T
        # plane n . X = 1 / h  =>  least squares for n / h, then trim and refit once
        keep = np.ones(len(P), bool)
        for _ in range(2):
            a, *_ = np.linalg.lstsq(P[keep], np.ones(keep.sum()), rcond=None)
            r = np.abs(P @ a - 1.0)
            keep = r < max(3 * np.median(r[keep]), 1e-6)
        heights.append(1.0 / np.linalg.norm(a))
    if not heights:
        raise ValueError("no frame has enough traversable pixels to fit the ground plane")
    return camera_height / float(np.median(heights))


def travel_direction(poses: np.ndarray) -> np.ndarray | None:
    """The median direction of travel in the camera frame over the steps of ``poses`` (camera to
    world) that moved: the car drives along the road, so this is the road's forward direction as
    the camera sees it, whatever the steps' lengths. None when no step moved."""
    dirs = []
    for a, b in itertools.pairwise(poses):
        c = (np.linalg.inv(a) @ b)[:3, 3]          # camera centre of the next frame, in this one
        if np.linalg.norm(c) > 1e-9:
            dirs.append(c / np.linalg.norm(c))
    if not dirs:
        return None
    d = np.median(np.array(dirs), axis=0)
    return d / np.linalg.norm(d)
