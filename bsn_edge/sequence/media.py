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
