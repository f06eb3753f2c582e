"""``bsn-calibrate --mount``: a camera file's mounting from a short straight drive."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.calibration.hood import Hood, HoodConfig, find_hood
from bsn_edge.calibration.lane_height import LaneHeight
from bsn_edge.calibration.mount_fit import MountFit, MountFitConfig
from bsn_edge.mounting import REFERENCE_HEIGHT_M, check_height
from bsn_edge.sequence.media import read_video

LANE_WIDTH_RANGE_M = (2.0, 6.0)   # marking centre to marking centre, narrow urban lanes to wide highway ones
HOOD_SPAN = 120                   # frames the hood is looked for in, from the first


class MountingRefusedError(ValueError):
    """The clip does not allow the estimate; the message says why, with the counts."""


def check_arguments(height_m: float | None, lane_width_m: float | None) -> None:
    """``ValueError`` for a height or lane width out of range, before any frame is read."""
    if height_m is not None:
        check_height(height_m, "--height")
    lo, hi = LANE_WIDTH_RANGE_M
    if lane_width_m is not None and not (math.isfinite(lane_width_m) and lo <= lane_width_m <= hi):
        raise ValueError(f"--lane-width must lie in [{lo:g}, {hi:g}] metres, got {lane_width_m:g}")


def calibrate_mounting(video: str | os.PathLike, camera: Calibration, height_m: float | None = None,
                       lane_width_m: float | None = None, cfg: MountFitConfig | None = None,
                       max_frames: int | None = None,
                       progress: Callable[[int], None] | None = None) -> Calibration:
    """``camera`` with its mounting from ``video``: pitch, yaw and roll from the drive, the height
    measured (``height_m``) or from the lane width. Raises :class:`MountingRefusedError`."""
    if (height_m is None) == (lane_width_m is None):
        raise ValueError("give the camera's height (--height) or the lane width (--lane-width), one of them")
    check_arguments(height_m, lane_width_m)
    path = Path(video)
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found")
    frames = read_video(path, max_frames, progress)
    # the intrinsics are rescaled to the video's size, but another aspect ratio is another camera
    if frames:
        camera.fit_to(frames[0].shape[1], frames[0].shape[0], where=f"the camera file for {path}")
    h, w = (frames[0].shape[:2]) if frames else (camera.intrinsics.height, camera.intrinsics.width)
    intr = camera.intrinsics.scaled(w, h)
    fit = MountFit(intr, camera.dist, cfg or MountFitConfig())
    for f in frames:
        fit.add(f)
    m, report = fit.estimate(height_m or REFERENCE_HEIGHT_M)
    report["frames"] = len(frames)
    if m is None or not report["converged"]:
        raise MountingRefusedError(_why(report, fit.cfg))
    if lane_width_m is not None:
        lanes = LaneHeight(intr, camera.dist, m)
        for f in frames:
            lanes.add(f)
        hm, lane_report = lanes.estimate(lane_width_m)
        report["height"] = lane_report
        if hm is None:
            raise MountingRefusedError(f"the lane markings were clear in {lane_report['frames_used']} of {len(frames)} "
                                  f"frames (need 5): measure the height and give --height")
        m = type(m)(hm, m.pitch_deg, m.yaw_deg, m.roll_deg)
    else:
        report["height"] = {"method": "measured", "height_m": height_m}
    return camera.with_mounting(m, **report).with_hood(hood_of(frames))


def hood_of(frames: Sequence[np.ndarray]) -> Hood:
    """The hood in a clip: looked for over its first seconds, ``HoodConfig.frames`` frames spread over
    the first ``HOOD_SPAN`` (a clip's frame rate is not known here; about 3 s at 30 frames/s)."""
    n = HoodConfig().frames
    span = frames[:HOOD_SPAN]
    step = max(1, len(span) // n)
    return find_hood(span[::step][:n])


def _why(report: dict, cfg: MountFitConfig) -> str:
    rejected = ", ".join(f"{k}: {v}" for k, v in sorted(report["rejected"].items())) or "none"
    head = (f"{report['used']} of {report['pairs']} frame pairs were usable (need {cfg.min_pairs}; "
            f"rejected: {rejected})")
    if report["frames"] <= cfg.gap + cfg.min_pairs:
        return f"the clip is too short ({report['frames']} frames): {head}; record at least 10 s of straight driving"
    if report["used"] < cfg.min_pairs:
        return f"{head}; drive straight ahead at a steady speed (not turning, not standing still)"
    se = report.get("standard_error_deg", {})
    return (f"{head}, but the estimate has not settled (standard error pitch {se.get('pitch', 0):.2f}, yaw "
            f"{se.get('yaw', 0):.2f} degrees, need <= {cfg.max_spread_deg}); record a longer straight drive")
