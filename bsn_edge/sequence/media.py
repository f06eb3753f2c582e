"""File kinds a clip or a frame source can come in: image and video extensions, one list each,
and reading a whole (short) video."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp")
VIDEO_EXTS = (".mp4", ".avi", ".mkv", ".mov", ".m4v")


JPEG_SOS, JPEG_EOI = b"\xff\xda", b"\xff\xd9"
PNG_IEND = b"IEND\xaeB`\x82"


def picture_damage(data: bytes, suffix: str) -> str | None:
    """Why a JPEG or PNG file's bytes are not a whole picture, or None. A decoder fills what a cut file
    lacks (libjpeg only warns "Premature end of JPEG file"), so a cut is found here: a JPEG whose
    entropy-coded data has no end-of-image marker after it, a PNG without its end chunk."""
    kind = suffix.lower()
    if kind in (".jpg", ".jpeg"):
        if not data.startswith(b"\xff\xd8"):
            return "not a JPEG (no start-of-image marker)"
        sos = data.find(JPEG_SOS)
        if sos < 0 or data.rfind(JPEG_EOI) < sos:
            return "a cut JPEG (its image data has no end-of-image marker)"
    elif kind == ".png" and PNG_IEND not in data[-64:]:
        return "a cut PNG (no end chunk)"
    return None


def is_image(path: str | Path) -> bool:
    return Path(path).suffix.lower() in IMAGE_EXTS


def is_video(path: str | Path) -> bool:
    return Path(path).suffix.lower() in VIDEO_EXTS


def read_video(path: str | os.PathLike, max_frames: int | None = None,
               progress: Callable[[int], None] | None = None) -> list[np.ndarray]:
    """The decodable frames of a video file, in order (BGR); ``ValueError`` if OpenCV cannot open it."""
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise ValueError(f"{path}: OpenCV cannot open this video")
    frames: list[np.ndarray] = []
    try:
        while max_frames is None or len(frames) < max_frames:
            ok, frame = cap.read()
            if not ok:
                break
            frames.append(frame)
            if progress:
                progress(1)
    finally:
        cap.release()
    return frames
