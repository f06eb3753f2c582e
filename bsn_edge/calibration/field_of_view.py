"""A camera known only by its field of view: the camera file a specification sheet gives.

Without a chessboard, the horizontal field of view on a dashcam's box or data sheet still fixes the
focal length: a pinhole with square pixels and its principal point at the frame's centre. It knows
no lens distortion, so it suits cameras of moderate width; a wide-angle lens bends straight lines
more and more towards the edges, which only the chessboard step (``calibrate``) models.
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import cv2

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.sequence.media import IMAGE_EXTS, VIDEO_EXTS, is_image, is_video, read_video

HFOV_RANGE_DEG = (20.0, 150.0)   # a forward camera's field of view, outside it a typing error is likelier
WIDE_DEG = 100.0                  # above this a lens without distortion is a rough stand-in


def frame_size(source: str | os.PathLike) -> tuple[int, int]:
    """(width, height) of the first frame of a video, or of the first image of a folder."""
    p = Path(source)
    if p.is_dir():
        first = next((q for q in sorted(p.iterdir()) if is_image(q)), None)
        if first is None:
            raise ValueError(f"{p}: no image in this folder ({', '.join(IMAGE_EXTS)})")
        img = cv2.imread(str(first), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"{first}: OpenCV cannot read this image")
        return img.shape[1], img.shape[0]
    if not p.exists():
        raise FileNotFoundError(f"{p} not found")
    if not is_video(p):
        raise ValueError(f"{p}: give a video ({', '.join(VIDEO_EXTS)}) or a folder of its frames")
    frames = read_video(p, max_frames=1)
    if not frames:
        raise ValueError(f"{p}: OpenCV cannot read a frame of this video")
    return frames[0].shape[1], frames[0].shape[0]


def from_field_of_view(source: str | os.PathLike, hfov_deg: float) -> Calibration:
    """The camera file of the camera that took ``source`` (a video or a folder of its frames), from
    its horizontal field of view in degrees: intrinsics only, no distortion, no mounting. Above
    ``WIDE_DEG`` the lens's distortion, which this cannot know, grows large (the caller says so)."""
    lo, hi = HFOV_RANGE_DEG
    if not lo <= hfov_deg <= hi:
        raise ValueError(f"a forward camera's horizontal field of view is within {lo:g}-{hi:g} degrees, "
                         f"got {hfov_deg:g}")
    w, h = frame_size(source)
    return replace(Calibration.of(Intrinsics.from_fov(w, h, hfov_deg)),
                   intrinsics_method=f"field of view: {hfov_deg:g} degrees across")
