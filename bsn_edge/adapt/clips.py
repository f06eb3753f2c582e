"""A user's recordings (videos, image folders, sequence folders) -> sequence folders of frames only.

Only frames and the camera are taken: a sequence folder's depth, segmentation, poses and true
blind spots are never copied, so nothing downstream can read them.
"""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.sequence.folder import SequenceFolder, frame_name
from bsn_edge.sequence.media import IMAGE_EXTS, VIDEO_EXTS, is_video
from bsn_edge.sequence.meta import SequenceMeta

JPEG_QUALITY = 95
FLOW_WIDTH = 320        # frames are compared at this width for the motion check
MOVING_PX = 0.5         # median corner motion per frame (at FLOW_WIDTH) above which the car moves


class UnusableClipError(ValueError):
    """A recording that cannot be adapted on (unreadable, too short, standing still, no road)."""


@dataclass(frozen=True)
class Imported:
    """One recording as a sequence folder: where, from what, how many frames at what rate."""

    name: str
    path: Path
    source: str
    frames: int
    fps: float
    camera: str          # where its camera came from


def clip_name(source: Path, taken: set[str]) -> str:
    """A folder name for ``source`` that no other recording of this adaptation has."""
    stem = source.stem if source.is_file() or is_video(source) else source.name
    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", stem) or "clip"
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    return name


def _frames_of(source: Path, fps: float | None, max_fps: float) -> tuple[list[Path] | cv2.VideoCapture, float, int]:
    """What to read (image paths, or an opened video), the source's rate and the keep-every step."""
    if source.is_file() and is_video(source):
        cap = cv2.VideoCapture(str(source))
        if not cap.isOpened():
            raise UnusableClipError(f"{source}: OpenCV cannot open this video")
        rate = float(cap.get(cv2.CAP_PROP_FPS) or 0) or (fps or 0)
        if not rate > 0:
            cap.release()
            raise UnusableClipError(f"{source}: the video does not say its frame rate; pass --fps")
        return cap, rate, max(1, round(rate / max_fps))
    if source.is_dir():
        seq = SequenceFolder(source)
        if seq.meta_path.is_file():
            rate = SequenceMeta.read(source).fps
            paths = [seq.rgb(i) for i in seq.rgb_frames()]
        else:
            paths = sorted(p for p in source.iterdir() if p.suffix.lower() in IMAGE_EXTS)
            if fps is None:
                raise UnusableClipError(f"{source}: a folder of images has no frame rate; pass --fps")
            rate = fps
        if not paths:
            raise UnusableClipError(f"{source}: no frame images found")
        return paths, rate, max(1, round(rate / max_fps))
    raise UnusableClipError(f"{source}: not a video ({', '.join(VIDEO_EXTS)}), a folder of images or a sequence "
                            "folder")


def _camera_of(source: Path, calib: Calibration | None, w: int, h: int,
               model_hfov_deg: float) -> tuple[Calibration, str]:
    """The imported clip's camera and where it came from: ``calib``, else a sequence folder's own camera
    file or meta, else assumed with the model camera's field of view."""
    if calib is not None:
        return calib, str(calib.mounting_report.get("method", "--calib"))
    if source.is_dir() and SequenceFolder(source).calibration_path.is_file():
        return Calibration.read(SequenceFolder(source).calibration_path), "the clip's camera file"
    if source.is_dir() and SequenceFolder(source).meta_path.is_file():
        return Calibration.of(SequenceMeta.read(source).intrinsics, method="the clip's meta"), "the clip's meta"
    how = f"assumed: no --calib, the model camera's {model_hfov_deg:g} degree field of view"
    return Calibration.of(Intrinsics.from_fov(w, h, model_hfov_deg), method=how), how


def import_clip(source: str | Path, dest: Path, calib: Calibration | None, model_hfov_deg: float,
                fps: float | None = None, max_fps: float = 10.0,
                progress: Callable[[int], None] | None = None) -> Imported:
    """Write ``source``'s frames (at most ``max_fps`` a second) into the sequence folder ``dest``
    with a meta and a camera file: ``calib``, else a sequence folder's own camera file, else an
    assumed camera with the model camera's field of view (said in ``Imported.camera``). A finished
    import (its meta written last) is kept as it is."""
    source = Path(source)
    seq = SequenceFolder(dest)
    if seq.meta_path.is_file() and seq.rgb_frames():
        meta = SequenceMeta.read(dest)
        cam = Calibration.read(seq.calibration_path).mounting_report.get("method", "calibration")
        return Imported(dest.name, dest, str(source), meta.frames, meta.fps, str(cam))
    if not source.exists():
        raise UnusableClipError(f"{source}: not found")
    src, rate, step = _frames_of(source, fps, max_fps)
    shutil.rmtree(dest, ignore_errors=True)          # an unfinished import starts again
    rgb = dest / SequenceFolder.RGB
    rgb.mkdir(parents=True)
    n, size = 0, None

    def put(img: np.ndarray | None, what: str) -> None:
        nonlocal n, size
        if img is None:
            raise UnusableClipError(f"{what}: unreadable image")
        if size is not None and img.shape[:2] != size:
            raise UnusableClipError(f"{what}: {img.shape[1]}x{img.shape[0]}, the clip's frames are "
                                    f"{size[1]}x{size[0]}")
        size = img.shape[:2]
        cv2.imwrite(str(rgb / frame_name(n, ".jpg")), img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        n += 1
        if progress:
            progress(1)

    if isinstance(src, list):
        for p in src[::step]:
            put(cv2.imread(str(p), cv2.IMREAD_COLOR), str(p))
    else:
        k = 0
        try:
            while True:
                ok, frame = src.read()
                if not ok:
                    break
                if k % step == 0:
                    put(frame, f"{source} frame {k}")
                k += 1
        finally:
            src.release()
    if n == 0 or size is None:
        raise UnusableClipError(f"{source}: no frame could be read")
    h, w = size
    cam, how = _camera_of(source, calib, w, h, model_hfov_deg)
    cam.write(seq.calibration_path)
    SequenceMeta(fps=rate / step, intrinsics=cam.intrinsics.scaled(w, h),
                 source=f"bsn-adapt: {source}", frames=n).write(dest)
    return Imported(dest.name, dest, str(source), n, rate / step, how)


def moving_seconds(seq: Path, fps: float) -> float:
    """Seconds of the clip in which the image moves (median corner motion between neighbouring
    frames above ``MOVING_PX`` at ``FLOW_WIDTH``): a car standing still gives none."""
    s = SequenceFolder(seq)
    frames = s.rgb_frames()
    prev, moving = None, 0
    for i in frames:
        img = cv2.imread(str(s.rgb(i)), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise ValueError(f"{s.rgb(i)}: not a picture OpenCV can read")
        g = cv2.resize(img, (FLOW_WIDTH, round(img.shape[0] * FLOW_WIDTH / img.shape[1])),
                       interpolation=cv2.INTER_AREA)
        if prev is not None:
            pts = cv2.goodFeaturesToTrack(prev, 200, 0.01, 7)
            if pts is not None and len(pts) >= 10:
                nxt, ok, _ = cv2.calcOpticalFlowPyrLK(prev, g, pts, None)
                d = np.linalg.norm((nxt - pts)[ok.ravel() == 1], axis=-1)
                if len(d) >= 10 and float(np.median(d)) > MOVING_PX:
                    moving += 1
        prev = g
    return moving / fps
