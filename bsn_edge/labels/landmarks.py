"""Sparse landmarks: corners of a frame triangulated with the clip's poses.

They carry the poses' scale, so a relative depth map aligned to them (``align.py``) lives
in the same units as the trajectory that warps it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from bsn_edge.tracks import Matches, detect, track, triangulate

BASELINE_S = 0.5   # look this many seconds ahead (or back at the clip's end) for parallax
AGREE = 0.1        # depths from the full and the half baseline must agree this closely


def frame_landmarks(gray: Callable[[int], np.ndarray], i: int, n_frames: int, fps: float,
                    poses: np.ndarray, K: np.ndarray, matches: Matches | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, v, depth)`` of corners of frame ``i`` triangulated against a frame a short baseline
    away, tracked through the frames between.

    A corner is kept only if triangulating it at half the baseline gives the same depth (within
    ``AGREE``): a tracker that slips along the direction of motion (lane-marking dashes, rows of
    windows) passes every epipolar test, but its error does not grow with the baseline as true
    parallax does. ``matches(i, j)`` (frames far apart in time) replaces tracking: the points of
    frame ``i`` matched to both frames are kept.
    """
    s = max(2, round(BASELINE_S * fps))
    step = 1 if i + s < n_frames else -1
    if not 0 <= i + step * s < n_frames:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    if matches is not None:
        p0, p1, ph = _matched_in_both(matches, i, i + step * s, i + step * (s // 2))
    else:
        p0, p1, ph = _tracked(gray, i, step, s)
    if len(p0) < 8:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    z, ok = triangulate(K, poses[i], poses[i + step * s], p0, p1)
    zh, okh = triangulate(K, poses[i], poses[i + step * (s // 2)], p0, ph)
    with np.errstate(divide="ignore", invalid="ignore"):
        agree = np.abs(zh - z) < AGREE * z
    keep = ok & agree & (okh | (zh > 0))
    return p0[keep, 0], p0[keep, 1], z[keep]


def _tracked(gray: Callable[[int], np.ndarray], i: int, step: int, s: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corners of frame ``i``, tracked ``s`` frames on: in ``i``, at the end and half way."""
    g = gray(i)
    p0 = detect(g)
    pts, alive = p0.copy(), np.ones(len(p0), bool)
    prev, half_pts = g, p0
    for k in range(1, s + 1):
        nxt = gray(i + step * k)
        p, ok = track(prev, nxt, pts)
        pts, alive, prev = p, alive & ok, nxt
        if k == s // 2:
            half_pts = pts.copy()
    return p0[alive], pts[alive], half_pts[alive]


def _matched_in_both(matches: Matches, i: int, far: int, half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points of frame ``i`` matched to frame ``far`` and to frame ``half``."""
    a0, a1 = matches(i, far)
    b0, b1 = matches(i, half)
    at_half = {tuple(p): q for p, q in zip(b0.tolist(), b1, strict=True)}
    keep = [k for k, p in enumerate(a0.tolist()) if tuple(p) in at_half]
    if not keep:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2))
    return a0[keep], a1[keep], np.array([at_half[tuple(a0[k].tolist())] for k in keep])
