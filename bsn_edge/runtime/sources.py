"""Frame sources for the runtime: video files, image folders, cameras and streams.

Each yields ``Captured(t, frame, index)``; ``frame`` is None for a frame that could not be
decoded (the loop counts it and goes on). Files run frame by frame on the video's own clock
(optionally paced to real time); live sources run on the wall clock through a reader thread
that keeps only the newest frame and counts the ones it had to drop.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.calibration.frames import IMAGE_EXTS


@dataclass(frozen=True)
class Captured:
    t: float                     # seconds on the source's clock
    frame: np.ndarray | None
    index: int
    decode_s: float = 0.0


class Source:
    """Base: iterate to get frames; ``dropped`` counts frames a live source had to skip."""

    live = False
    dropped = 0

    def __iter__(self) -> Iterator[Captured]:
        raise NotImplementedError

    def close(self) -> None:
        pass


class VideoFileSource(Source):
    def __init__(self, path: str | Path, pace: bool = False) -> None:
        self.path = Path(path)
        self.cap = cv2.VideoCapture(str(self.path))
        if not self.cap.isOpened():
            raise ValueError(f"{self.path}: OpenCV cannot open this video")
        self.fps = self.cap.get(cv2.CAP_PROP_FPS) or 10.0
        self.total = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT)) or None
        self.pace = pace

    def __iter__(self) -> Iterator[Captured]:
        start = time.monotonic()
        i = 0
        failures = 0
        while True:
            t0 = time.perf_counter()
            ok, frame = self.cap.read()
            dt = time.perf_counter() - t0
            if not ok:
                # a broken frame in the middle of a file is skipped; the end of the file stops
                if self.total is not None and i < self.total - 1 and failures < 10:
                    failures += 1
                    yield Captured(i / self.fps, None, i, dt)
                    i += 1
                    continue
                return
            failures = 0
            t = i / self.fps
            if self.pace:
                wait = start + t - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            yield Captured(t, frame, i, dt)
            i += 1

    def close(self) -> None:
        self.cap.release()


class ImageFolderSource(Source):
    def __init__(self, folder: str | Path, fps: float = 10.0) -> None:
        self.folder = Path(folder)
        rgb = self.folder / "rgb"
        root = rgb if rgb.is_dir() else self.folder
        self.files = sorted(p for p in root.iterdir() if p.suffix.lower() in IMAGE_EXTS)
        if not self.files:
            raise ValueError(f"{self.folder}: no images ({', '.join(IMAGE_EXTS)})")
        self.fps = fps

    def __iter__(self) -> Iterator[Captured]:
        for i, p in enumerate(self.files):
            t0 = time.perf_counter()
            frame = cv2.imread(str(p), cv2.IMREAD_COLOR)
            yield Captured(i / self.fps, frame, i, time.perf_counter() - t0)


class LiveSource(Source):
    """A camera index or a stream URL, read by a thread that keeps only the newest frame."""

    live = True

    def __init__(self, target: int | str) -> None:
        self.target = target
        self.cap = cv2.VideoCapture(target)
        if not self.cap.isOpened():
            raise ValueError(f"cannot open camera or stream {target!r}")
        self._lock = threading.Lock()
        self._newest: Captured | None = None
        self._taken = True
        self._stop = threading.Event()
        self._ended = threading.Event()
        self._thread = threading.Thread(target=self._read, name="bsn-capture", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        i = 0
        while not self._stop.is_set():
            t0 = time.perf_counter()
            ok, frame = self.cap.read()
            dt = time.perf_counter() - t0
            if not ok:
                self._ended.set()
                return
            with self._lock:
                if not self._taken:
                    self.dropped += 1
                self._newest, self._taken = Captured(time.monotonic(), frame, i, dt), False
            i += 1

    def __iter__(self) -> Iterator[Captured]:
        while not self._stop.is_set():
            with self._lock:
                item, fresh = self._newest, not self._taken
                self._taken = True
            if fresh and item is not None:
                yield item
            elif self._ended.is_set():
                return
            else:
                time.sleep(0.002)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.cap.release()


def open_source(spec: str, pace: bool = False, fps: float = 10.0) -> Source:
    """``VIDEO`` file, image ``DIR``, camera index (``0``), or stream ``URL`` (``rtsp://...``)."""
    if spec.isdigit():
        return LiveSource(int(spec))
    if "://" in spec:
        return LiveSource(spec)
    p = Path(spec)
    if p.is_dir():
        return ImageFolderSource(p, fps)
    if p.is_file():
        return VideoFileSource(p, pace)
    raise FileNotFoundError(f"source {spec!r} is not a file, a folder, a camera index or a URL")
