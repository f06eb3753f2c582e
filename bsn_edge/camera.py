"""Pinhole intrinsics and camera poses (OpenCV camera frame: x right, y down, z forward).

Rescaling intrinsics to another image size happens here and nowhere else.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from bsn_edge.fields import number


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics ``fx fy cx cy`` at an image size of ``width`` x ``height`` pixels."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.height}x{self.width} (H x W)")
        if not (np.isfinite(self.fx) and np.isfinite(self.fy) and self.fx > 0 and self.fy > 0):
            raise ValueError(f"focal lengths must be positive and finite, got fx={self.fx} fy={self.fy}")
        if not (np.isfinite(self.cx) and np.isfinite(self.cy)):
            raise ValueError(f"principal point must be finite, got cx={self.cx} cy={self.cy}")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str = "intrinsics") -> Intrinsics:
        """Every field required and numeric; ``ValueError`` names the field and ``where``."""
        fx, fy, cx, cy = (float(number(d, k, where)) for k in ("fx", "fy", "cx", "cy"))
        width, height = (int(number(d, k, where, int)) for k in ("width", "height"))
        return cls(fx, fy, cx, cy, width, height)

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> Intrinsics:
        """Square pixels, centred principal point, horizontal field of view in degrees."""
        if not 1.0 < hfov_deg < 179.0:
            raise ValueError(f"horizontal field of view must be in (1, 179) degrees, got {hfov_deg}")
        f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2.0)
        return cls(float(f), float(f), width / 2.0, height / 2.0, int(width), int(height))

    @property
    def K(self) -> np.ndarray:
        """3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, width: int, height: int) -> Intrinsics:
        """The same camera seen at another image size (pixel-centre convention)."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(
            self.fx * sx, self.fy * sy,
            (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5,
            int(width), int(height),
        )

    def rays(self) -> np.ndarray:
        """``[H, W, 3]`` float32 ray directions with unit z, so a ray's parameter is its depth."""
        u = (np.arange(self.width, dtype=np.float64) - self.cx) / self.fx
        v = (np.arange(self.height, dtype=np.float64) - self.cy) / self.fy
        out = np.empty((self.height, self.width, 3), dtype=np.float32)
        out[..., 0] = u[None, :]
        out[..., 1] = v[:, None]
        out[..., 2] = 1.0
        return out

    def to_dict(self) -> dict[str, float]:
        return {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
                "width": self.width, "height": self.height}


def look_pose(position: np.ndarray, yaw: float, pitch: float = 0.0) -> np.ndarray:
    """Camera-to-world ``T_wc`` for a camera at ``position`` in a z-up world.

    ``yaw`` is the heading in the world's x-y plane (0 looks along +x, counter-clockwise
    positive); ``pitch`` tilts the optical axis down when positive. Radians.
    """
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    forward = np.array([cy * cp, sy * cp, -sp])
    right = np.array([sy, -cy, 0.0])
    down = np.cross(forward, right)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = right, down, forward
    T[:3, 3] = position
    return T
