"""A synthetic clip's camera: field of view, mounting, lens distortion and the car's own hood.

With ``vary`` every clip draws its own from its seed, so a training set sees many dashcams:
horizontal field of view 50-110 degrees, height 1.1-1.9 m, pitch, yaw and roll of a few
degrees, barrel distortion on some, an ego hood across the bottom of some. The clip's
``calibration.json`` carries the result in the same camera file a user's camera has.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.mounting import REFERENCE_HEIGHT_M, Mounting

HFOV_DEG = (50.0, 110.0)
HEIGHT_M = (1.1, 1.9)
PITCH_DEG = (-2.0, 4.0)      # down positive
YAW_DEG = (-3.0, 3.0)
ROLL_DEG = (-2.0, 2.0)
BARREL = (0.0, 0.1)          # how much the image corner is pulled in, as a share of its radius
P_DISTORTED = 0.5
P_HOOD = 0.4
HOOD_ROWS = (0.06, 0.16)     # share of the image rows the hood covers at its centre


@dataclass(frozen=True)
class Rig:
    """How a synthetic clip's camera is built and mounted."""

    hfov_deg: float = 80.0
    height_m: float = REFERENCE_HEIGHT_M
    pitch_deg: float = 1.5
    yaw_deg: float = 0.0
    roll_deg: float = 0.0
    k1: float = 0.0
    hood: float = 0.0           # share of rows the hood covers at the centre column, 0 = none

    def __post_init__(self) -> None:
        if not 20.0 <= self.hfov_deg <= 150.0:
            raise ValueError(f"hfov_deg must be in [20, 150], got {self.hfov_deg}")
        if not -0.5 <= self.k1 <= 0.0:
            raise ValueError(f"k1 must be barrel distortion in [-0.5, 0], got {self.k1}")
        if not 0.0 <= self.hood <= 0.4:
            raise ValueError(f"hood must cover [0, 0.4] of the rows, got {self.hood}")
        self.mounting  # noqa: B018 - validates height and angles

    @classmethod
    def draw(cls, seed: int) -> Rig:
        rng = np.random.default_rng([seed, 0x726967])
        hfov = float(rng.uniform(*HFOV_DEG))
        k1 = 0.0
        if rng.random() < P_DISTORTED:
            # pull the corner in by a share s of its radius: r_d = r (1 + k1 r^2) with r the corner's
            r2 = math.tan(math.radians(hfov) / 2.0) ** 2 * (1.0 + 0.25)   # 2:1 frame: corner ~ 1.12 x the edge
            k1 = -float(rng.uniform(*BARREL)) / r2
        hood = float(rng.uniform(*HOOD_ROWS)) if rng.random() < P_HOOD else 0.0
        return cls(hfov, float(rng.uniform(*HEIGHT_M)), float(rng.uniform(*PITCH_DEG)), float(rng.uniform(*YAW_DEG)),
                   float(rng.uniform(*ROLL_DEG)), k1, hood)

    @property
    def mounting(self) -> Mounting:
        return Mounting(self.height_m, self.pitch_deg, self.yaw_deg, self.roll_deg)

    @property
    def dist(self) -> tuple[float, ...]:
        return (self.k1, 0.0, 0.0, 0.0, 0.0) if self.k1 else ()

    def intrinsics(self, width: int, height: int) -> Intrinsics:
        return Intrinsics.from_fov(width, height, self.hfov_deg)

    def calibration(self, width: int, height: int) -> Calibration:
        return Calibration.of(self.intrinsics(width, height), self.dist, self.mounting, method="synthetic rig")

    def to_dict(self) -> dict:
        return asdict(self)


class Lens:
    """Renders through a pinhole canvas large enough to hold the distorted view, then distorts.

    Without distortion the canvas is the image and :meth:`apply` is the identity."""

    def __init__(self, intrinsics: Intrinsics, dist: tuple[float, ...]) -> None:
        self.out = intrinsics
        self.dist = dist
        if not dist:
            self.canvas = intrinsics
            self.maps = None
            return
        K, d = intrinsics.K, np.asarray(dist, np.float64)
        w, h = intrinsics.width, intrinsics.height
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        und = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], -1)[:, None], K, d, P=K).reshape(h, w, 2)
        u0, v0 = np.floor(und[..., 0].min()) - 1, np.floor(und[..., 1].min()) - 1
        u1, v1 = np.ceil(und[..., 0].max()) + 2, np.ceil(und[..., 1].max()) + 2
        self.canvas = Intrinsics(intrinsics.fx, intrinsics.fy, intrinsics.cx - u0, intrinsics.cy - v0,
                                 int(u1 - u0), int(v1 - v0))
        self.maps = ((und[..., 0] - u0).astype(np.float32), (und[..., 1] - v0).astype(np.float32))

    def apply(self, img: np.ndarray, nearest: bool = False) -> np.ndarray:
        if self.maps is None:
            return img
        interp = cv2.INTER_NEAREST if nearest or img.dtype == bool else cv2.INTER_LINEAR
        src = img.view(np.uint8) if img.dtype == bool else img
        out = cv2.remap(src, *self.maps, interp, borderMode=cv2.BORDER_REPLICATE)
        return out.view(bool) if img.dtype == bool else out


def hood_mask(width: int, height: int, hood: float) -> np.ndarray:
    """The ego hood: a shallow arch across the bottom, ``hood`` of the rows deep at the centre."""
    if hood <= 0:
        return np.zeros((height, width), bool)
    x = (np.arange(width) - (width - 1) / 2.0) / (width / 2.0)
    top = height * (1.0 - hood * (1.0 - 0.45 * x ** 2))
    return np.arange(height)[:, None] >= top[None, :]


def paint_hood(rgb: np.ndarray, mask: np.ndarray, seed: int) -> None:
    """Paint the hood in place: a body colour with the sky's reflection fading down it."""
    if not mask.any():
        return
    rng = np.random.default_rng([seed, 0x686F6F64])
    body = rng.uniform(15, 200) * np.array([rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2)])
    rows = np.nonzero(mask.any(axis=1))[0]
    depth = (np.arange(rgb.shape[0]) - rows[0]) / max(len(rows), 1)
    shade = (0.55 + 0.45 * np.exp(-4.0 * np.clip(depth, 0, 1)))[:, None, None]
    colour = np.clip(body[None, None, :] * shade + 40.0 * np.exp(-8.0 * np.clip(depth, 0, 1))[:, None, None], 0, 255)
    full = np.broadcast_to(colour, rgb.shape).astype(np.uint8)
    rgb[mask] = full[mask]
