"""Sparse feature tracks between frames (OpenCV corners + pyramidal Lucas-Kanade)."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable

import cv2
import numpy as np

MAX_CORNERS = 1200
FB_MAX_PX = 1.0   # forward-backward consistency, pixels
WINDOW_PX = 21    # Lucas-Kanade window


def detect(gray: np.ndarray, mask: np.ndarray | None = None, max_corners: int = MAX_CORNERS) -> np.ndarray:
    """``[N, 2]`` float32 corner positions."""
    pts = cv2.goodFeaturesToTrack(gray, max_corners, 0.005, 6, mask=None if mask is None
                                  else mask.astype(np.uint8), blockSize=5)
    return np.zeros((0, 2), np.float32) if pts is None else pts.reshape(-1, 2)


def track(g0: np.ndarray, g1: np.ndarray, pts: np.ndarray, window: int = WINDOW_PX
          ) -> tuple[np.ndarray, np.ndarray]:
    """Track ``pts`` from ``g0`` to ``g1``; returns positions in ``g1`` and a mask of tracks that
    survive the forward-backward check. ``window``: the Lucas-Kanade window's side in pixels (the
    cost of a track grows with its area)."""
    if not len(pts):
        return pts, np.zeros(0, bool)
    p0 = pts.reshape(-1, 1, 2).astype(np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    p1, st1, _ = cv2.calcOpticalFlowPyrLK(g0, g1, p0, None, winSize=(window, window), maxLevel=3, criteria=criteria)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(g1, g0, p1, None, winSize=(window, window), maxLevel=3,
                                            criteria=criteria)
    fb = np.linalg.norm((back - p0).reshape(-1, 2), axis=1)
    h, w = g0.shape[:2]
    p1 = p1.reshape(-1, 2)
    ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (fb < FB_MAX_PX)
    ok &= (p1[:, 0] >= 0) & (p1[:, 0] < w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] < h - 1)
    return p1, ok


def triangulate(K: np.ndarray, T_w0: np.ndarray, T_w1: np.ndarray, p0: np.ndarray, p1: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Depths in camera 0 of matches ``p0 <-> p1`` and a mask of well-conditioned ones
    (in front of both cameras, reprojection under 1.5 px, parallax over 1 degree)."""
    T_10 = np.linalg.inv(T_w1) @ T_w0
    P0 = K @ np.eye(3, 4)
    P1 = K @ T_10[:3]
    X = cv2.triangulatePoints(P0, P1, p0.T.astype(np.float64), p1.T.astype(np.float64))
    X = (X[:3] / X[3]).T
    z0 = X[:, 2]
    X1 = X @ T_10[:3, :3].T + T_10[:3, 3]
    z1 = X1[:, 2]
    ok = (z0 > 0.1) & (z1 > 0.1)
    with np.errstate(divide="ignore", invalid="ignore"):
        r0 = (X @ K.T)[:, :2] / z0[:, None] - p0
        r1 = (X1 @ K.T)[:, :2] / z1[:, None] - p1
        c0 = X / np.linalg.norm(X, axis=1, keepdims=True)
        c1 = (X - (-T_10[:3, :3].T @ T_10[:3, 3])) / np.linalg.norm(
            X - (-T_10[:3, :3].T @ T_10[:3, 3]), axis=1, keepdims=True)
        parallax = np.degrees(np.arccos(np.clip((c0 * c1).sum(1), -1, 1)))
    ok &= (np.linalg.norm(r0, axis=1) < 1.5) & (np.linalg.norm(r1, axis=1) < 1.5) & (parallax > 1.0)
    return z0, ok


Matches = Callable[[int, int], tuple[np.ndarray, np.ndarray]]   # frames (i, j) -> points in i, points in j

SIFT_FEATURES = 8000
SIFT_CONTRAST = 0.02  # half OpenCV's default: dim city streets under cloud give few keypoints otherwise
RATIO = 0.8           # Lowe's ratio test; RANSAC removes what it lets through


class FeatureMatches:
    """Matches between frames too far apart in time for Lucas-Kanade (a clip at one frame a second
    moves tens of pixels between frames, its near road hundreds): SIFT keypoints on the pixels
    ``static(i)`` allows (classes that do not move: a car passing is not the camera moving),
    matched with the ratio test, on contrast-equalised frames. Each frame's keypoints are found once (the last
    :data:`KEEP` frames asked for are kept), so matches of frame ``i`` to two others start from the
    same points of ``i``."""

    KEEP = 8

    def __init__(self, gray: Callable[[int], np.ndarray], static: Callable[[int], np.ndarray] | None = None) -> None:
        self.gray, self.static = gray, static
        self._sift = cv2.SIFT.create(SIFT_FEATURES, contrastThreshold=SIFT_CONTRAST)
        self._clahe = cv2.createCLAHE(2.0, (8, 8))
        self._matcher = cv2.BFMatcher(cv2.NORM_L2)
        self._found: OrderedDict[int, tuple[np.ndarray, np.ndarray | None]] = OrderedDict()

    def _features(self, i: int) -> tuple[np.ndarray, np.ndarray | None]:
        if i in self._found:
            self._found.move_to_end(i)
            return self._found[i]
        mask = None
        if self.static is not None:
            mask = cv2.erode(self.static(i).astype(np.uint8) * 255, np.ones((3, 3), np.uint8))
        kp, des = self._sift.detectAndCompute(self._clahe.apply(self.gray(i)), mask)
        self._found[i] = (np.array([k.pt for k in kp], np.float32).reshape(-1, 2), des)
        while len(self._found) > self.KEEP:
            self._found.popitem(last=False)
        return self._found[i]

    def __call__(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Matched positions ``[N, 2]`` in frame ``i`` and in frame ``j``."""
        (pa, da), (pb, db) = self._features(i), self._features(j)
        if da is None or db is None or len(da) < 2 or len(db) < 2:
            return np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32)
        pairs = self._ratio(da, db)
        if not pairs:
            return np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32)
        ia, ib = np.array(pairs).T
        return pa[ia], pb[ib]

    def _ratio(self, da: np.ndarray, db: np.ndarray) -> list[tuple[int, int]]:
        out = []
        for m in self._matcher.knnMatch(da, db, k=2):
            if len(m) == 2 and m[0].distance < RATIO * m[1].distance:
                out.append((m[0].queryIdx, m[0].trainIdx))
        return out
