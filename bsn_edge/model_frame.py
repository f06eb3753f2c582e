"""The model frame: every camera's frames warped into the one camera the model knows.

A user's camera (intrinsics, lens distortion, mounting) and the model camera (the card's
intrinsics at the input size and its mounting: a reference height and a pitch, no yaw or roll)
sit at the same place in the car. One ``cv2.remap`` takes a raw frame straight to the model's
input (undistortion, rotation and scale in one step; a frame more than 1.5x finer than the model
camera is low-passed first); the inverse map brings outputs back onto
the raw frame. ``bsn-run``, ``bsn-label`` and the training data loader all use this class, so
every stage sees the same geometry.

Depth, honestly: the model frame's picture of a road seen from height ``h`` is exactly the
picture of the same world scaled by ``h_ref / h`` seen from the reference height, so a model
that learned the reference camera reads depths ``h_ref / h`` times the truth. Depth therefore
goes to the user's camera as ``z_model * h / h_ref`` (exact for the road plane; for everything
else as right as the model's use of the road as its scale), then from the model camera's axis
to the raw camera's (``z_raw = z_model * (R r)_z`` for the model ray ``r`` with unit z).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.mounting import REFERENCE_HEIGHT_M, Mounting, inverse_maps, warp_maps

SHRINK_ABOVE = 1.5   # raw-to-model pixel ratio above which pictures are low-passed before the remap


MODEL_HFOV_DEG = 80.0   # the model camera's horizontal field of view (training's default, on every card since)
MODEL_PITCH_DEG = 1.5   # and its pitch, down


def model_camera(size: tuple[int, int], hfov_deg: float = MODEL_HFOV_DEG, height_m: float = REFERENCE_HEIGHT_M,
                 pitch_deg: float = MODEL_PITCH_DEG) -> tuple[Intrinsics, Mounting]:
    """The model camera at ``size`` (H, W): its intrinsics and mounting (no yaw or roll)."""
    h, w = size
    return Intrinsics.from_fov(w, h, hfov_deg), Mounting(height_m, pitch_deg)


def block_mean(frame: np.ndarray, k: int) -> np.ndarray:
    """``frame`` averaged over whole ``k`` x ``k`` blocks, the last < ``k`` rows and columns left out:
    OpenCV's area resize at a whole factor (its fast path; at any other factor it is many times
    slower). Block (i, j) averages pixels k*i .. k*i + k - 1: its centre is k*i + (k - 1) / 2."""
    h, w = frame.shape[0] // k, frame.shape[1] // k
    return cv2.resize(frame[:h * k, :w * k], (w, h), interpolation=cv2.INTER_AREA)


def mirrored_inside(coord: np.ndarray, n: int) -> np.ndarray:
    """Source coordinates (pixel centres at 0 .. ``n`` - 1) mirrored into the picture as
    ``cv2.BORDER_REFLECT`` mirrors pixels (``fedcba|abcdef``, about -0.5 and ``n`` - 0.5), then held
    within 0 .. ``n`` - 1. A bilinear remap of these reads what a remap of ``coord`` with
    ``BORDER_REFLECT`` reads; but every tap falls inside the picture, so OpenCV takes its fast path
    instead of testing and reflecting each tap."""
    period = 2 * n
    m = np.mod(coord + 0.5, period) - 0.5
    m = np.where(m > n - 0.5, period - 1 - m, m)
    return np.clip(m, 0, n - 1).astype(np.float32)


class ModelFrame:
    """The warp between one raw camera at one frame size and the model camera.

    raw, dist, mounting:          the user's camera at the raw frame's size
    model, model_mounting:        the model camera (intrinsics at the model's input size)
    blocked:                      raw-frame pixels that show the car itself (its hood): not ``seen``
    """

    def __init__(self, raw: Intrinsics, dist: tuple[float, ...], mounting: Mounting, model: Intrinsics,
                 model_mounting: Mounting, blocked: np.ndarray | None = None) -> None:
        self.raw, self.dist, self.mounting = raw, tuple(float(d) for d in dist), mounting
        self.model, self.model_mounting = model, model_mounting
        mx, my = warp_maps(raw, self.dist, mounting, model, model_mounting)
        # model pixels whose ray falls outside the raw picture see nothing
        self.seen = (mx >= -0.5) & (mx <= raw.width - 0.5) & (my >= -0.5) & (my <= raw.height - 0.5)
        self._fwd_float = (mx, my)     # masks and depth: nearest, at the raw frame's full size
        if blocked is not None:        # nor do those that see the car itself (its hood)
            if blocked.shape != (raw.height, raw.width):
                raise ValueError(f"blocked must be {raw.height}x{raw.width} (the raw frame), got "
                                 f"{blocked.shape[0]}x{blocked.shape[1]}")
            self.seen &= self.labels_to_model(blocked.astype(np.uint8)) == 0
        # Pictures: a raw frame much finer than the model camera is low-passed first (a bilinear
        # remap alone would alias: every model pixel would sample one raw pixel of many). From twice
        # the model's scale up it is area-shrunk by the whole factor k = floor(factor) over k x k
        # blocks (OpenCV's area resize is fast for whole factors only), which leaves the remap
        # between 1 and 1.5. Then, from SHRINK_ABOVE up, the binomial [1, 2, 1] / 4 in both
        # directions (OpenCV's fixed 3-tap kernel) removes what the remap would fold back (an odd k
        # leaves a third of the finest stripes). Its cost and its distance from an exact area shrink
        # are in benchmarks/results/remap.md.
        factor = min(raw.fx / model.fx, raw.fy / model.fy)
        self.shrink = math.floor(factor) if factor >= 2 else 1
        self.prefilter = factor > SHRINK_ABOVE
        sx, sy = self.picture_maps()
        h, w = self.picture_size
        # fixed point, mirrored inside: the fast path of remap
        self._fwd = cv2.convertMaps(mirrored_inside(sx, w), mirrored_inside(sy, h), cv2.CV_16SC2)
        ix, iy = inverse_maps(raw, self.dist, mounting, model, model_mounting)
        self._inv = (ix, iy)
        self.height_ratio = mounting.height_m / model_mounting.height_m
        # raw-camera z of the point at unit model-camera z along each model pixel's ray
        r_raw_from_model = mounting.rotation() @ model_mounting.rotation().T
        z_raw_per_model = (model.rays().reshape(-1, 3) @ r_raw_from_model[2]).reshape(model.height, model.width)
        self._to_model_depth = (1.0 / (self.height_ratio * z_raw_per_model)).astype(np.float32)
        self._to_raw_depth = (self.height_ratio * self.to_raw(z_raw_per_model.astype(np.float32))).astype(np.float32)

    @classmethod
    def resize_only(cls, model: Intrinsics, model_mounting: Mounting, width: int, height: int) -> ModelFrame:
        """A camera that is the model camera at another size: the warp is a plain resize."""
        return cls(model.scaled(width, height), (), model_mounting, model, model_mounting)

    @classmethod
    def undistort_only(cls, camera: Intrinsics, dist: tuple[float, ...], mounting: Mounting) -> ModelFrame:
        """The lens taken out and nothing else: the same pinhole camera, pose and size, undistorted."""
        return cls(camera, dist, mounting, camera, mounting)

    # -- raw -> model --------------------------------------------------------------------------

    @property
    def picture_size(self) -> tuple[int, int]:
        """(H, W) of the picture the remap reads: the raw frame, or its k x k blocks."""
        return self.raw.height // self.shrink, self.raw.width // self.shrink

    def picture_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """Where each model pixel samples the picture the remap reads (:meth:`low_passed`), before
        mirroring: raw coordinates, or block coordinates after a shrink by k."""
        k = self.shrink
        mx, my = self._fwd_float
        # a block's centre is raw k*i + (k - 1) / 2 (block_mean)
        return (mx - (k - 1) / 2) / k, (my - (k - 1) / 2) / k

    @property
    def fixed_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`picture_maps` mirrored into the picture (every bilinear tap inside it) in OpenCV's
        fixed point: what :meth:`to_model` remaps with."""
        return self._fwd

    def low_passed(self, frame: np.ndarray) -> np.ndarray:
        """The picture the remap reads: the raw frame area-shrunk by k and low-passed as the model
        camera needs (itself when it needs neither)."""
        self._check(frame)
        if self.shrink > 1:
            frame = block_mean(frame, self.shrink)
        if self.prefilter:
            frame = cv2.GaussianBlur(frame, (3, 3), 0)
        return frame

    def to_model(self, frame: np.ndarray, dst: np.ndarray | None = None,
                 interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """A raw frame (any channels) in the model camera. Where the raw camera sees nothing the
        picture is mirrored from its edge (training and the runtime alike; ``seen`` says where):
        a frame in a black border is a look no model has learned."""
        return cv2.remap(self.low_passed(frame), *self.fixed_maps, interpolation, dst=dst,
                         borderMode=cv2.BORDER_REPLICATE)

    def labels_to_model(self, labels: np.ndarray) -> np.ndarray:
        """Masks and class ids: nearest neighbour, 0 where the raw camera sees nothing."""
        self._check(labels)
        return cv2.remap(labels, *self._fwd_float, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)

    def depth_to_model(self, depth: np.ndarray) -> np.ndarray:
        """A raw camera's z-depth (metres, 0 = none) as the model camera at its reference height
        would read it: nearest neighbour, converted along the model's rays, scaled by ``h_ref / h``."""
        self._check(depth)
        d = cv2.remap(depth.astype(np.float32), *self._fwd_float, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        return np.where(d > 0, d * self._to_model_depth, 0.0).astype(np.float32)

    # -- model -> raw --------------------------------------------------------------------------

    def to_raw(self, arr: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """A model-frame image or map back on the raw frame's pixels; 0 where the model frame does not reach."""
        if arr.shape[:2] != (self.model.height, self.model.width):
            raise ValueError(f"expected a {self.model.height}x{self.model.width} model-frame array, got "
                             f"{arr.shape[0]}x{arr.shape[1]}")
        return cv2.remap(arr, *self._inv, interpolation, borderMode=cv2.BORDER_CONSTANT)

    def depth_to_raw(self, depth: np.ndarray) -> np.ndarray:
        """The model's depth (model camera, reference height) as the raw camera's z-depth in metres,
        on the raw frame's pixels; 0 where the model frame does not reach."""
        return self.to_raw(depth.astype(np.float32), cv2.INTER_NEAREST) * self._to_raw_depth

    def depth_to_metres(self, depth: np.ndarray) -> np.ndarray:
        """The model's depth in the model camera's own axes at the user's true scale (forward distance)."""
        return depth * np.float32(self.height_ratio)

    def raw_column_sector(self, column_sector: np.ndarray) -> np.ndarray:
        """Per raw-frame column, the sector of the model column it meets on the raw frame's middle row."""
        x = self._inv[0][self.raw.height // 2]
        idx = np.clip(np.rint(x), 0, self.model.width - 1).astype(np.intp)
        return column_sector[idx]

    def _check(self, frame: np.ndarray) -> None:
        if frame.shape[:2] != (self.raw.height, self.raw.width):
            raise ValueError(f"frame is {frame.shape[0]}x{frame.shape[1]}, this camera's warp was built for "
                             f"{self.raw.height}x{self.raw.width}")
