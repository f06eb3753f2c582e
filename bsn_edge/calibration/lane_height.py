"""The camera's height above the road from a known lane width.

With pitch, yaw and roll known, the road is seen from above (a bird's-eye view computed for a
camera one unit above the road, so lateral positions come in units of the height). The ego
lane's two markings are the strongest bright stripes either side of the car's axis; their
separation ``s`` (in heights) and the lane's width ``W`` (metres) give the height ``W / s``.
Each frame gives an estimate; the median is used and the spread reported. Frames without two
clear markings are skipped and counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.mounting import Mounting

LATERAL = (-4.0, 4.0)      # bird's-eye view across, in camera heights
AHEAD = (5.0, 14.0)        # and ahead (about 7-20 m for a car's camera)
STEP = 0.01                # heights per bird's-eye pixel across
ROW_STEP = 0.05            # and along
MARKING = 0.25             # wider bright things than this (heights) are not markings
MIN_PEAK_RATIO = 3.0       # a marking's response over the profile's median


@dataclass
class LaneHeight:
    """Feed frames of one camera with a known pitch, yaw and roll; ask :meth:`estimate`."""

    intrinsics: Intrinsics
    dist: tuple[float, ...]
    mounting: Mounting
    separations: list[float] = field(default_factory=list)
    skipped: int = 0
    _maps: tuple[np.ndarray, np.ndarray] | None = None

    def _build(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        k = self.intrinsics.scaled(width, height)
        xs = np.arange(LATERAL[0], LATERAL[1], STEP)
        zs = np.arange(AHEAD[1], AHEAD[0], -ROW_STEP)           # far at the top
        X, Z = np.meshgrid(xs, zs)
        level = np.stack([X, np.ones_like(X), Z], -1).reshape(-1, 3)   # the road, one unit below
        cam = level @ self.mounting.rotation().T
        pts, _ = cv2.projectPoints(cam, np.zeros(3), np.zeros(3), k.K, np.asarray(self.dist or (), np.float64))
        pts = pts.reshape(len(zs), len(xs), 2).astype(np.float32)
        self._maps = (pts[..., 0], pts[..., 1])
        return self._maps

    def add(self, frame: np.ndarray) -> bool:
        gray = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        mx, my = self._maps if self._maps is not None else self._build(gray.shape[1], gray.shape[0])
        bev = cv2.remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        size = round(MARKING / STEP) | 1
        resp = cv2.morphologyEx(bev, cv2.MORPH_TOPHAT, np.ones((1, size), np.uint8)).astype(np.float32)
        profile = cv2.GaussianBlur(resp.mean(axis=0)[None], (0, 0), 2.0).ravel()
        xs = LATERAL[0] + STEP * np.arange(len(profile))
        floor = float(np.median(profile)) + 1e-3
        left = (xs > -3.0) & (xs < -0.3)
        right = (xs > 0.3) & (xs < 3.0)
        il, ir = np.argmax(np.where(left, profile, -1)), np.argmax(np.where(right, profile, -1))
        if min(profile[il], profile[ir]) < MIN_PEAK_RATIO * floor:
            self.skipped += 1
            return False
        self.separations.append(float(xs[ir] - xs[il]))
        return True

    def estimate(self, lane_width_m: float) -> tuple[float | None, dict[str, Any]]:
        """The height (metres) and a report: frames used and skipped, spread."""
        n = len(self.separations)
        report: dict[str, Any] = {"method": f"lane width {lane_width_m:g} m", "frames_used": n,
                                  "frames_skipped": self.skipped}
        if n < 5:
            return None, report
        h = lane_width_m / np.array(self.separations)
        med = float(np.median(h))
        report.update(height_m=med, spread_m=float(1.4826 * np.median(np.abs(h - med))))
        return med, report
