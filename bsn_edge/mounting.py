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
from dataclasses import dataclass

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics


@dataclass(frozen=True)
class Mounting:
    """Height of the optical centre above the road (metres) and the optical axis's angles (degrees)."""

    height_m: float
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    roll_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.height_m) and 0.2 <= self.height_m <= 5.0):
            raise ValueError(f"height_m must lie in [0.2, 5] metres, got {self.height_m}")
        for name in ("pitch_deg", "yaw_deg", "roll_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and abs(v) <= 30.0):
                raise ValueError(f"{name} must lie in [-30, 30] degrees, got {v}")

    def rotation(self) -> np.ndarray:
        """``R`` with ``x_cam = R @ x_level``: a level-frame vector in this camera's frame."""
        p, y, r = (math.radians(a) for a in (self.pitch_deg, self.yaw_deg, self.roll_deg))
        # the camera's axes in the level frame: yaw about y, then pitch about x, then roll about z
        ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
        rx = np.array([[1, 0, 0], [0, math.cos(p), math.sin(p)], [0, -math.sin(p), math.cos(p)]])
        rz = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
        axes = ry @ rx @ rz   # columns: the camera's x, y, z in the level frame
        return axes.T


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
    u, v = np.meshgrid(np.arange(raw.width, dtype=np.float64), np.arange(raw.height, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], -1)[:, None, :]
    out = cv2.undistortPoints(pts, raw.K, np.asarray(dist, np.float64), R=r_model_from_raw, P=model.K)
    out = out.reshape(raw.height, raw.width, 2).astype(np.float32)
    return out[..., 0], out[..., 1]
