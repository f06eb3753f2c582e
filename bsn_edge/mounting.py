"""How a camera sits in the car, and the warp from a user's camera into the model camera.

Groundwork for the any-camera flow: one remap takes a raw frame (distorted, any size, any
mounting) to the model camera's pixels (undistortion, rotation and scale in one ``cv2.remap``),
and the inverse map brings the model's outputs back onto the raw frame.

Frames: the *level* frame is OpenCV's camera frame of a camera at the same place looking along
the car's axis, parallel to the road (x right, y down, z forward). A mounting's angles, in
degrees, turn the camera away from it, in this order: ``yaw`` (the optical axis to the right when
positive), ``pitch`` (the optical axis down when positive), ``roll`` (the camera's x axis down
when positive, so the picture turns the other way).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.fields import number

REFERENCE_HEIGHT_M = 1.5       # a car's dashcam: the model camera's height, and the height where none is known
HEIGHT_RANGE_M = (0.2, 5.0)     # a camera's height above the road: every tool checks against this one range
ANGLE_LIMIT_DEG = 30.0          # pitch, yaw and roll
INVERSE_BAND_ROWS = 64


def check_height(height_m: float, what: str = "height_m") -> float:
    """``height_m`` if it is a camera height :data:`HEIGHT_RANGE_M` admits, else ``ValueError``."""
    lo, hi = HEIGHT_RANGE_M
    if not (math.isfinite(height_m) and lo <= height_m <= hi):
        raise ValueError(f"{what} must lie in [{lo:g}, {hi:g}] metres, got {height_m:g}")
    return height_m


@dataclass(frozen=True)
class Mounting:
    """Height of the optical centre above the road (metres) and the optical axis's angles (degrees)."""

    height_m: float
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    roll_deg: float = 0.0

    def __post_init__(self) -> None:
        check_height(self.height_m)
        for name in ("pitch_deg", "yaw_deg", "roll_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and abs(v) <= ANGLE_LIMIT_DEG):
                raise ValueError(f"{name} must lie in [-{ANGLE_LIMIT_DEG:g}, {ANGLE_LIMIT_DEG:g}] degrees, got {v}")

    def rotation(self) -> np.ndarray:
        """``R`` with ``x_cam = R @ x_level``: a level-frame vector in this camera's frame."""
        p, y, r = (math.radians(a) for a in (self.pitch_deg, self.yaw_deg, self.roll_deg))
        # the camera's axes in the level frame: yaw about y, then pitch about x, then roll about z
        ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
        rx = np.array([[1, 0, 0], [0, math.cos(p), math.sin(p)], [0, -math.sin(p), math.cos(p)]])
        rz = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
        axes = ry @ rx @ rz   # columns: the camera's x, y, z in the level frame
        return axes.T

    @classmethod
    def from_axes(cls, axes: np.ndarray, height_m: float) -> Mounting:
        """The mounting whose camera axes (the columns of ``axes``) are these, in the level frame."""
        pitch, yaw, roll = angles_of(axes)
        return cls(float(height_m), pitch, yaw, roll)

    @classmethod
    def from_forward(cls, forward_cam: np.ndarray, height_m: float, roll_deg: float = 0.0) -> Mounting:
        """Pitch and yaw from the car's direction of travel seen in the camera frame (the focus of
        expansion of a straight drive), with the roll given."""
        t = np.asarray(forward_cam, np.float64)
        t = t / np.linalg.norm(t)
        # undo the roll first: it turns the whole picture about the optical axis
        r = math.radians(roll_deg)
        rz = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
        x, y, z = rz @ t
        # for zero roll, the level forward axis seen from the camera is
        # (-sin yaw, -sin pitch cos yaw, cos pitch cos yaw)
        yaw = -math.asin(float(np.clip(x, -1.0, 1.0)))
        pitch = math.atan2(-float(y), float(z))
        return cls(float(height_m), math.degrees(pitch), math.degrees(yaw), float(roll_deg))

    def horizon_row(self, intrinsics: Intrinsics) -> float:
        """Image row of the level horizon at the principal column (rows grow downwards)."""
        d = self.rotation() @ np.array([0.0, 0.0, 1.0])
        return float(intrinsics.cy + intrinsics.fy * d[1] / d[2])

    def to_dict(self) -> dict[str, float]:
        return {"height_m": self.height_m, "pitch_deg": self.pitch_deg, "yaw_deg": self.yaw_deg,
                "roll_deg": self.roll_deg}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str = "mounting") -> Mounting:
        """Every field is required: a file without its pitch is not a camera at pitch 0 (a wrong pitch
        skews every distance on the bus)."""
        return cls(*(number(d, key, where) for key in ("height_m", "pitch_deg", "yaw_deg", "roll_deg")))



def angles_of(axes: np.ndarray) -> tuple[float, float, float]:
    """Pitch, yaw and roll (degrees, unchecked) of the camera whose axes in the level frame are the
    columns of ``axes``."""
    a = np.asarray(axes, np.float64)
    z = a[:, 2]
    pitch = math.asin(float(np.clip(z[1], -1.0, 1.0)))
    yaw = math.atan2(float(z[0]), float(z[2]))
    # what is left once yaw and pitch are undone is the roll about the optical axis
    ry = np.array([[math.cos(yaw), 0, math.sin(yaw)], [0, 1, 0], [-math.sin(yaw), 0, math.cos(yaw)]])
    rx = np.array([[1, 0, 0], [0, math.cos(pitch), math.sin(pitch)], [0, -math.sin(pitch), math.cos(pitch)]])
    rz = (ry @ rx).T @ a
    roll = math.atan2(float(rz[1, 0]), float(rz[0, 0]))
    return math.degrees(pitch), math.degrees(yaw), math.degrees(roll)


def warp_maps(raw: Intrinsics, dist: tuple[float, ...], mounting: Mounting, model: Intrinsics,
              model_mounting: Mounting) -> tuple[np.ndarray, np.ndarray]:
    """``(map_x, map_y)`` float32 ``[H, W]`` of the model camera's size: for each model pixel, where
    to sample the raw frame (``cv2.remap(raw_frame, map_x, map_y, ...)``). Both cameras are at the
    same place; only their orientation, intrinsics and lens differ."""
    r_model_from_raw = model_mounting.rotation() @ mounting.rotation().T
    return cv2.initUndistortRectifyMap(raw.K, np.asarray(dist, np.float64), r_model_from_raw, model.K,
                                       (model.width, model.height), cv2.CV_32FC1)


def inverse_maps(raw: Intrinsics, dist: tuple[float, ...], mounting: Mounting, model: Intrinsics,
                 model_mounting: Mounting) -> tuple[np.ndarray, np.ndarray]:
    """``(map_x, map_y)`` float32 ``[H, W]`` of the raw frame's size: for each raw pixel, where to
    sample the model's outputs to bring them back onto the raw frame."""
    r_model_from_raw = model_mounting.rotation() @ mounting.rotation().T
    k, d = raw.K, np.asarray(dist, np.float64)
    map_x = np.empty((raw.height, raw.width), np.float32)
    map_y = np.empty_like(map_x)
    u = np.arange(raw.width, dtype=np.float64)
    # a band of rows at a time: a full HD frame's points in float64 would cost ~50 MB at once
    for top in range(0, raw.height, INVERSE_BAND_ROWS):
        rows = np.arange(top, min(top + INVERSE_BAND_ROWS, raw.height), dtype=np.float64)
        pts = np.empty((rows.size, raw.width, 2), np.float64)
        pts[..., 0], pts[..., 1] = u, rows[:, None]
        out = cv2.undistortPoints(pts.reshape(-1, 1, 2), k, d, R=r_model_from_raw, P=model.K)
        out = out.reshape(rows.size, raw.width, 2)
        map_x[top:top + rows.size], map_y[top:top + rows.size] = out[..., 0], out[..., 1]
    return map_x, map_y
