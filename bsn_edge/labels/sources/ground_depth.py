"""Depth from the road plane and the camera's mounting, for clips whose depth model does not fit.

A camera at height ``h`` whose mounting (pitch, roll) is known sees flat ground at the depth
``h / (down . ray)`` of each pixel's ray, where ``down`` is the road normal in the camera frame.
Things that stand on the ground (cars, people, poles, walls, trees) are taken as standing
upright on their ground contact, the stixel model: each pixel of them gets the depth of the
first ground pixel below it in its column, when the thing's class runs down to it (otherwise
its contact is hidden and its depth stays unknown). Where that holds (a flat road near the car, upright
objects) this depth needs no network at all; where it does not (hills, a wrong mounting, an
overhang), the landmarks say so: the source is aligned and checked like any depth model
(``AlignedDepth``), and a clip it does not fit is refused.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.camera import Intrinsics
from bsn_edge.labels.sources.base import ClipData, ClipRejectedError, DepthSource, SegSource
from bsn_edge.labels.sources.onnx_depth import AlignedDepth
from bsn_edge.model_frame import ModelFrame
from bsn_edge.mounting import Mounting
from bsn_edge.tracks import Matches

if TYPE_CHECKING:
    from bsn_edge.labels.config import LabelConfig

GROUND: tuple[int, ...] = (sm.ROAD, sm.SIDEWALK, sm.TERRAIN)   # classes that lie on the ground plane
MAX_GROUND_M = 80.0   # beyond this a pixel row spans metres of road: no depth is claimed there


def ground_depth(sem: np.ndarray, intrinsics: Intrinsics, mounting: Mounting,
                 max_depth: float = MAX_GROUND_M) -> np.ndarray:
    """Metric depth ``[H, W]`` float32 of a trainId image seen by a camera so mounted: ground
    classes on the road plane, other classes (sky excepted) at the depth of the ground just
    below them in their column (the image bottom when none is) if their class runs down to it;
    NaN where unknown (sky, the ignore id, things whose contact is hidden by another class,
    ground above the horizon or beyond ``max_depth``)."""
    h, w = sem.shape
    if (h, w) != (intrinsics.height, intrinsics.width):
        raise ValueError(f"segmentation is {w}x{h} but the camera is {intrinsics.width}x{intrinsics.height}")
    down = mounting.rotation() @ np.array([0.0, 1.0, 0.0])     # the road's normal, pointing down, in the camera
    u = (np.arange(w) - intrinsics.cx) / intrinsics.fx

    def plane_at(rows: np.ndarray) -> np.ndarray:
        v = (rows - intrinsics.cy) / intrinsics.fy
        dot = down[0] * u[None, :] + down[1] * v[:, None] + down[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(dot > 0, mounting.height_m / dot, np.inf)
        return np.where(z <= max_depth, z, np.nan)

    centre = plane_at(np.arange(h, dtype=np.float64))
    # an object's contact lies on the boundary between its last row and the ground's first
    plane = plane_at(np.arange(h + 1, dtype=np.float64) - 0.5)
    ground = np.isin(sem, GROUND)
    # per column, the first ground row at or below each pixel (h where there is none)
    rows = np.where(ground, np.arange(h)[:, None], h)
    below = np.minimum.accumulate(rows[::-1], axis=0)[::-1]
    # a thing's contact is only seen when its own class runs unbroken down to that ground row: a
    # building above a parked car stands somewhere behind the car, at a depth no column tells
    change = np.ones((h, w), bool)
    change[:-1] = sem[:-1] != sem[1:]
    run_end = np.minimum.accumulate(np.where(change, np.arange(h)[:, None], h)[::-1], axis=0)[::-1]
    grounded = run_end + 1 == below
    cols = np.broadcast_to(np.arange(w), (h, w))
    contact = plane[below, cols]              # the boundary row above the first ground pixel
    depth = np.where(ground, centre, np.where(grounded, contact, np.nan))
    depth[(sem == sm.SKY) | (sem == sm.IGNORE)] = np.nan
    return depth.astype(np.float32)


class GroundDepth(AlignedDepth):
    """``ground``: depth from the segmentation and the mounting (``ground_depth``), checked against
    the landmarks with the same rule as a depth model's; the scale fit takes the odometry's units
    (the plane is metric already)."""

    mounting: Mounting

    name = "ground"

    @staticmethod
    def predictor(clip: ClipData, seg: SegSource, mounting: Mounting | None = None
                  ) -> tuple[Callable[[int], np.ndarray], Mounting]:
        """The plane's depth of frame ``i`` on the clip's raw pixels (NaN where unknown), before any
        check against the landmarks, and the mounting it comes from (``mounting``, else the camera
        file's)."""
        cal = clip.info.get("calibration")
        mounting = mounting or (cal.mounting if cal is not None else None)
        if mounting is None:
            raise ClipRejectedError("depth from the road plane needs the camera's mounting (height, pitch, roll): "
                                    "give a camera file with one (bsn-calibrate --mount)")
        intr = clip.meta.intrinsics
        if cal is not None and cal.has_distortion:
            # the plane holds in the undistorted camera; the depth goes back onto the raw pixels,
            # where every source's depth lives (the generator undistorts them all alike)
            lens = ModelFrame(intr, cal.dist, mounting, intr, mounting)

            def predict(i: int) -> np.ndarray:
                raw = lens.depth_to_raw(np.nan_to_num(ground_depth(lens.labels_to_model(seg(i)), intr, mounting)))
                return np.where(raw > 0, raw, np.nan).astype(np.float32)
        else:
            def predict(i: int) -> np.ndarray:
                return ground_depth(seg(i), intr, mounting)
        return predict, mounting

    @classmethod
    def for_clip(cls, clip: ClipData, seg: SegSource, poses: np.ndarray, cfg: LabelConfig,
                 frames: list[int], window: int | None = None, matches: Matches | None = None,
                 mounting: Mounting | None = None) -> GroundDepth:
        predict, mounting = cls.predictor(clip, seg, mounting)
        obj = cls(predict, "metric_depth", clip, poses, frames, cfg.min_corr, window, matches)
        obj.mounting = mounting
        return obj

    def __call__(self, i: int) -> np.ndarray:
        return np.nan_to_num(super().__call__(i), nan=0.0)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "kind": "ground", "mounting": self.mounting.to_dict(),
                "ground_classes": [sm.NAMES[c] for c in GROUND], "max_depth_m": MAX_GROUND_M}


class PlaneDepth(DepthSource):
    """The road plane's depth as it is, for poses whose steps were measured in it (``bsn-label --depth
    ground --poses vo``): the plane defines the metres, so there is no scale to fit to landmarks."""

    name = "ground"

    def __init__(self, predict: Callable[[int], np.ndarray], mounting: Mounting, mounting_from: str) -> None:
        self.predict, self.mounting, self.mounting_from = predict, mounting, mounting_from

    def __call__(self, i: int) -> np.ndarray:
        return np.nan_to_num(self.predict(i), nan=0.0)

    def describe(self) -> dict[str, Any]:
        return {"kind": "ground", "prediction": "metric_depth", "scale": "the plane's own (poses measured in it)",
                "mounting": self.mounting.to_dict(), "mounting_from": self.mounting_from,
                "ground_classes": [sm.NAMES[c] for c in GROUND], "max_depth_m": MAX_GROUND_M}
