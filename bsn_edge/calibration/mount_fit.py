"""The camera's mounting from driving video.

Pitch and yaw come from the focus of expansion of straight driving: frame to frame, the
essential matrix of tracked corners gives the camera's direction of travel in its own frame,
which on a straight road is the car's forward axis. This is preferred over the vanishing point
of lane lines because it needs no lane markings (towns, car parks, snow) and uses hundreds of
corners per frame instead of two lines. Roll comes from the road plane: corners on the road
below the horizon move by a homography whose plane normal, given the motion, is the road's
"down" seen from the camera. Pairs where the car turns (rotation above ``max_turn_deg``),
stands still (too little flow) or the geometry is weak are not used, and a clip that leaves too
few usable pairs is refused with the reasons counted.

The same estimator serves ``bsn-calibrate --mount`` (a whole clip, offline) and ``bsn-run``'s
online calibration (until the estimate has converged).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.model_frame import block_mean
from bsn_edge.mounting import Mounting, angles_of
from bsn_edge.tracks import MAX_CORNERS, WINDOW_PX, detect, track

MAX_ROLL_DEG = 15.0        # a camera rolled further is not mounted for driving
ESSENTIAL_FITS = {"usac": cv2.USAC_ACCURATE, "ransac": cv2.RANSAC}
SLOW_ROAD = 0.4            # a low corner moving slower than this share of the median road rate is not road


@dataclass(frozen=True)
class MountFitConfig:
    """When a frame pair counts, and when the estimate is good enough.

    min_flow_px:    median corner motion below this (at the working width): standing still
    max_turn_deg:   rotation between the two frames above this: turning
    min_inliers:    essential-matrix inliers a pair needs
    min_pairs:      usable pairs an estimate needs
    gap:            a pair is a frame and the one ``gap`` frames before it (more parallax than
                    neighbours give, so a steadier direction of travel)
    max_spread_deg: the estimate has converged when the robust spread (1.4826 MAD) of pitch and
                    yaw over the pairs, divided by sqrt(pairs), is below this
    work_width:     frames are tracked at about this width (wider frames are shrunk first)
    max_corners:    corners tracked per pair at most (the cost of a pair grows with them)
    window_px:      the optical flow's window (the cost of a corner grows with its area)
    essential:      the essential matrix's robust fit: ``usac`` (OpenCV's USAC_ACCURATE, GC-RANSAC
                    with local optimisation, which refines the direction of travel on its inliers) or
                    ``ransac`` (the best minimal sample's; pair to pair its pitch and yaw scatter about
                    4x wider, benchmarks/results/calibration.md)
    """

    min_flow_px: float = 1.0
    max_turn_deg: float = 0.6
    min_inliers: int = 40
    min_pairs: int = 20
    max_spread_deg: float = 0.15
    gap: int = 3
    work_width: int = 640
    max_corners: int = MAX_CORNERS
    window_px: int = WINDOW_PX
    essential: str = "usac"

    def __post_init__(self) -> None:
        if self.essential not in ESSENTIAL_FITS:
            raise ValueError(f"essential must be one of {', '.join(ESSENTIAL_FITS)}, got {self.essential!r}")
        if self.min_flow_px <= 0 or self.max_turn_deg <= 0 or self.min_inliers < 8 or self.min_pairs < 3:
            raise ValueError("min_flow_px and max_turn_deg must be positive, min_inliers >= 8, min_pairs >= 3")
        if self.work_width < 160 or self.max_corners < 2 * self.min_inliers or not 5 <= self.window_px <= 41:
            raise ValueError(f"work_width must be >= 160, max_corners >= 2 * min_inliers and window_px within "
                             f"5..41, got {self.work_width}, {self.max_corners} and {self.window_px}")


@dataclass
class MountFit:
    """Accumulates frame pairs of one camera; ask :meth:`estimate` at any time."""

    intrinsics: Intrinsics
    dist: tuple[float, ...] = ()
    cfg: MountFitConfig = field(default_factory=MountFitConfig)
    forward: list[np.ndarray] = field(default_factory=list)      # unit travel directions, camera frame
    down: list[np.ndarray] = field(default_factory=list)         # unit road normals (down), camera frame
    rejected: dict[str, int] = field(default_factory=dict)
    pairs: int = 0
    _prev: list[np.ndarray] = field(default_factory=list)
    _scale: float = 1.0
    _K: np.ndarray | None = None

    def add(self, frame: np.ndarray) -> bool:
        """Feed the next frame (BGR or gray, the calibration's camera at any size); True when the
        pair it closes was used."""
        gray = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        h, w = gray.shape
        if self._K is None:
            self._scale = min(1.0, self.cfg.work_width / w)
            k = self.intrinsics.scaled(round(w * self._scale), round(h * self._scale))
            self._K = k.K
        if self._scale < 1.0:
            gray = shrink(gray, (round(w * self._scale), round(h * self._scale)))
        if self._prev and self._prev[-1].shape != gray.shape:
            self._prev.clear()
        self._prev.append(gray)
        if len(self._prev) <= self.cfg.gap:
            return False
        prev = self._prev.pop(0)
        self.pairs += 1
        why = self._pair(prev, gray, self._K)
        if why:
            self.rejected[why] = self.rejected.get(why, 0) + 1
            return False
        return True

    def _pair(self, g0: np.ndarray, g1: np.ndarray, K: np.ndarray) -> str:
        p0 = detect(g0, max_corners=self.cfg.max_corners)
        if len(p0) < self.cfg.min_inliers:
            return "too few corners"
        p1, ok = track(g0, g1, p0, window=self.cfg.window_px)
        p0, p1 = p0[ok], p1[ok]
        if len(p0) < self.cfg.min_inliers:
            return "too few tracked corners"
        if np.median(np.linalg.norm(p1 - p0, axis=1)) < self.cfg.min_flow_px:
            return "standing still"
        d = np.asarray(self.dist, np.float64) if self.dist else None
        n0 = cv2.undistortPoints(p0[:, None].astype(np.float64), K, d).reshape(-1, 2)
        n1 = cv2.undistortPoints(p1[:, None].astype(np.float64), K, d).reshape(-1, 2)
        E, mask = cv2.findEssentialMat(n0, n1, np.eye(3), ESSENTIAL_FITS[self.cfg.essential], 0.999,
                                       1.0 / K[0, 0])
        if E is None or E.shape != (3, 3):
            return "no essential matrix"
        n, R, t, mask = cv2.recoverPose(E, n0, n1, np.eye(3), mask=mask)
        if n < self.cfg.min_inliers:
            return "too few inliers"
        if math.degrees(np.linalg.norm(cv2.Rodrigues(R)[0])) > self.cfg.max_turn_deg:
            return "turning"
        # X1 = R X0 + t: the camera moves by c = -R^T t (in frame 0's axes)
        c = -R.T @ t.ravel()
        c /= np.linalg.norm(c)
        if c[2] < 0.9:
            return "not driving forward"
        self.forward.append(c)
        # the road plane from the corners that fit the motion (the car's own hood does not move)
        inl = mask.ravel() > 0
        nd = _road_normal(n0[inl], n1[inl], R, t.ravel() / np.linalg.norm(t), c)
        if nd is not None:
            self.down.append(nd)
        return ""

    def estimate(self, height_m: float) -> tuple[Mounting | None, dict[str, Any]]:
        """The mounting from the pairs so far (``None`` when there are too few) and a report:
        pairs used, rejected by reason, spread of each angle, converged or not."""
        used = len(self.forward)
        report: dict[str, Any] = {"method": "focus of expansion (essential matrix) for pitch and yaw, road-plane "
                                            "homography for roll", "pairs": self.pairs, "used": used,
                                  "rejected": dict(self.rejected), "converged": False}
        if used < 3:
            return None, report
        fwd = np.array(self.forward)
        angles = np.array([_pitch_yaw(f) for f in fwd])
        pitch, yaw = np.median(angles, axis=0)
        spread = 1.4826 * np.median(np.abs(angles - [pitch, yaw]), axis=0)
        roll, roll_spread = 0.0, None
        if len(self.down) >= 3:
            f = _unit(np.median(fwd, axis=0))
            rolls = np.array([_roll(f, d) for d in self.down])
            rolls = rolls[np.abs(rolls) <= MAX_ROLL_DEG]     # a road-plane fit that failed
        if len(self.down) >= 3 and len(rolls) >= 3:
            roll = float(np.median(rolls))
            roll_spread = float(1.4826 * np.median(np.abs(rolls - roll)))
        m = Mounting.from_forward(_forward_of(pitch, yaw), height_m, roll)
        se = spread / math.sqrt(used)
        report.update(pitch_deg=m.pitch_deg, yaw_deg=m.yaw_deg, roll_deg=m.roll_deg,
                      spread_deg={"pitch": float(spread[0]), "yaw": float(spread[1]), "roll": roll_spread},
                      standard_error_deg={"pitch": float(se[0]), "yaw": float(se[1])},
                      road_plane_pairs=len(self.down),
                      converged=bool(used >= self.cfg.min_pairs and max(se) <= self.cfg.max_spread_deg))
        return m, report


def shrink(gray: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``gray`` at ``size`` (W, H), smaller: averaged over whole k x k blocks first (``block_mean``),
    then bilinear for what is left (under 2x, where bilinear hardly aliases)."""
    w, h = size
    k = min(gray.shape[1] // w, gray.shape[0] // h)
    if k >= 2:
        gray = block_mean(gray, k)
    if (gray.shape[1], gray.shape[0]) == (w, h):
        return gray
    return cv2.resize(gray, (w, h), interpolation=cv2.INTER_LINEAR)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _pitch_yaw(forward: np.ndarray) -> tuple[float, float]:
    """Pitch and yaw (degrees, zero roll) of a camera that sees the car's forward axis as ``forward``."""
    m = Mounting.from_forward(forward, 1.0)
    return m.pitch_deg, m.yaw_deg


def _forward_of(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    return Mounting(1.0, float(pitch_deg), float(yaw_deg)).rotation() @ np.array([0.0, 0.0, 1.0])


def _roll(forward: np.ndarray, down: np.ndarray) -> float:
    """Roll (degrees) of the camera whose view of the car's forward axis and of the road's down
    direction are these."""
    z = _unit(forward - (forward @ down) * down)
    x = np.cross(down, z)
    axes_cam_from_level = np.stack([x, down, z], axis=1)   # columns: level x, y, z in camera axes
    return angles_of(axes_cam_from_level.T)[2]


def _road_normal(n0: np.ndarray, n1: np.ndarray, R: np.ndarray, t: np.ndarray, forward: np.ndarray
                 ) -> np.ndarray | None:
    """The road's down direction from corners low in the picture: for the plane ``m . X0 = 1``
    (``m = n / d``), ``X1 = (R + t m^T) X0``; solved for ``m`` by least squares, robustly."""
    # corners well below the horizon and near the middle: mostly road
    fx, fy = forward[0] / forward[2], forward[1] / forward[2]
    low = (n0[:, 1] > fy + 0.12) & (np.abs(n0[:, 0] - fx) < 0.6)
    # A road point's flow grows as its offset from the focus of expansion times its depth below
    # the horizon; a car driving ahead at the ego's speed hardly moves in the picture, and an
    # essential matrix of pure forward motion counts it as an inlier. Its corners would pull the
    # plane: drop corners that move far less than the road's law says.
    rate = np.linalg.norm(n1 - n0, axis=1) / np.maximum(np.linalg.norm(n0 - [fx, fy], axis=1)
                                                        * (n0[:, 1] - fy), 1e-9)
    if low.sum() >= 15:
        low &= rate > SLOW_ROAD * np.median(rate[low])
    if low.sum() < 15:
        return None
    x0 = np.c_[n0[low], np.ones(low.sum())]
    x1 = np.c_[n1[low], np.ones(low.sum())]
    keep = np.ones(len(x0), bool)
    m = np.zeros(3)
    for _ in range(3):
        # x1 is parallel to (R + t m^T) x0: x1 x (t (m . x0)) = -x1 x (R x0), three rows per corner
        a, b = x0[keep], x1[keep]
        rows = (np.cross(b, t)[:, :, None] * a[:, None, :]).reshape(-1, 3)
        rhs = -np.cross(b, a @ R.T).reshape(-1)
        m = np.linalg.lstsq(rows, rhs, rcond=None)[0]
        pred = x0 @ (R + np.outer(t, m)).T
        err = np.linalg.norm(pred[:, :2] / pred[:, 2:] - x1[:, :2], axis=1)
        keep = err < max(3.0 * np.median(err), 1e-4)
        if keep.sum() < 10:
            return None
    nd = _unit(m)
    return nd if nd[1] > 0.8 else None
