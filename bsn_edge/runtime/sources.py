"""Frame sources for the runtime: video files, image folders, cameras and streams.

Each yields ``Captured(t, frame, index)`` (cameras and streams: :mod:`~bsn_edge.runtime.live_source`);
``frame`` is None for a frame that could not be decoded (the loop counts it and goes on). Files run frame by
frame on the video's own clock (optionally paced to real time); live sources run on the wall clock through a
reader thread that keeps only the newest frame and counts the ones it had to drop.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from bsn_edge.calibration.folder_cameras import FolderCameras, FolderVerdict, judge_folder
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.media import IMAGE_EXTS, is_image, picture_damage
from bsn_edge.sequence.picture_header import declared_size, within_budget
from bsn_edge.user_file import read_user_file

if TYPE_CHECKING:
    from bsn_edge.runtime.live_source import Reconnect

# the folder's size is the commonest of its first pictures' (their headers only); a JPEG's frame header
# sits after its EXIF and tables, within the first 64 KiB of any camera's file
SIZE_FROM = 9
HEADER_BYTES = 1 << 16


@dataclass(frozen=True)
class Captured:
    t: float                     # seconds on the source's clock
    frame: np.ndarray | None
    index: int
    decode_s: float = 0.0
    name: str = ""               # what saved maps are named after: an image's stem, else the frame number
    picture: Path | None = None  # the file the frame was read from, when it is a picture


def capture_size(cap) -> tuple[int, int] | None:
    """(width, height) an OpenCV capture reports, or None when it reports none."""
    w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH) or 0), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT) or 0)
    return (w, h) if w > 0 and h > 0 else None


MJPEG = cv2.VideoWriter.fourcc(*"MJPG")


def as_packets(cap) -> bool:
    """Switch an MJPEG capture (a file or a stream) to its packets, each decoded here as its own
    picture: FFmpeg scales every picture of such a stream to the first one's size, so a portrait
    picture in a landscape stream would arrive squashed to the stream's size and run as if nothing
    had changed. Whether the capture now delivers packets."""
    try:
        if int(cap.get(cv2.CAP_PROP_FOURCC)) != MJPEG:
            return False
        return bool(cap.set(cv2.CAP_PROP_FORMAT, -1))
    except (cv2.error, AttributeError, TypeError):    # a backend (or a test's stand-in) without the setting
        return False


def read_frame(cap, packets: bool) -> tuple[bool, np.ndarray | None]:
    """``cap.read()``; with ``packets`` the packet decoded at the size its own header declares (None for
    a packet that is no picture within the pixel budget: a frame that did not decode)."""
    ok, frame = cap.read()
    if not ok or frame is None or not packets:
        return ok, frame
    data = np.ascontiguousarray(frame).reshape(-1)
    if not within_budget(declared_size(data[:HEADER_BYTES].tobytes())):
        return True, None
    try:
        return True, cv2.imdecode(data, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    except cv2.error:
        return True, None


class Source:
    """Base: iterate to get frames; ``dropped`` counts frames a live source had to skip while the loop
    ran (``before_start`` those it replaced before the loop first asked: the model was still warming
    up, no frame was due yet); ``failure`` says why a source ended before its end (None when it ended normally).

    The base owns the policy every source shares: ``stop()`` ends the iteration early, from any thread
    (safe to call from a signal handler: it only sets an event, then :meth:`_on_stop`), no frame is
    handed out once stopped, and ``close()`` stops before it lets go (:meth:`_release`). A backend fills
    :meth:`_frames`, which may stop early by watching :attr:`stopped`."""

    live = False
    pace = False                 # a file's or folder's frames handed out no sooner than their own times
    fps = 10.0                   # frames per second of the source's own clock (a file's, a folder's; nominal when live)
    dropped = 0
    before_start = 0
    reconnects = 0
    unread = 0                   # frames of a file that never decoded at its end (counted as decode errors)
    failure: str | None = None
    size: tuple[int, int] | None = None   # (width, height) of its frames when known before the first one
    picture: Path | None = None           # the first frame's file when the frames are pictures (EXIF: the lens)
    cameras: FolderVerdict | None = None  # a folder's pictures: one camera or each its own (None: one camera)

    @property
    def one_camera(self) -> bool:
        """Whether every frame comes from one camera (a folder of unrelated photos does not)."""
        return self.cameras is None or self.cameras.cameras is FolderCameras.ONE

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 wait: Callable[[float], bool] | None = None) -> None:
        """``clock`` and ``wait``: what pacing reads and how it waits (``wait(s)`` is True when a stop
        came meanwhile; by default a wait a stop ends at once); injected in tests."""
        self._stop = threading.Event()
        self._clock = clock
        self._wait = wait or self._stop.wait

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def __iter__(self) -> Iterator[Captured]:
        start = None
        for cap in self._frames():
            if self.stopped:
                return
            if self.pace and not self.live:        # a live source is paced by its camera
                start = self._clock() - cap.t if start is None else start
                # a stop wakes the wait at once: the run ends on a signal, not after the frame's time
                due = start + cap.t - self._clock()
                if due > 0 and self._wait(due):
                    return
            yield cap

    def _frames(self) -> Iterator[Captured]:
        """The backend's frames, in order (the hook)."""
        raise NotImplementedError

    def stop(self) -> None:
        self._stop.set()
        self._on_stop()

    def _on_stop(self) -> None:
        """Wake whatever the backend waits on (a thread, a slot)."""

    def close(self) -> None:
        self.stop()
        self._release()

    def _release(self) -> None:
        """Let go of the device or file."""


class VideoFileSource(Source):
    """A video file on its own clock. Frames are known by their timestamps, not by counting reads:
    where the decoder skips a damaged stretch (OpenCV jumps to the next keyframe, often without a
    failed read) the frames it skipped are counted there, as ``None`` frames the loop counts, and the
    frames after it keep their true times and indices. A file that stops decoding for ``give_up``
    frames in a row before its end has failed."""

    def __init__(self, path: str | Path, pace: bool = False, give_up: int = 250, decode_threads: int = 1,
                 clock: Callable[[], float] = time.monotonic, wait: Callable[[float], bool] | None = None) -> None:
        """``decode_threads``: FFmpeg's decoding threads (0: its own choice, one per core). One by default:
        the frame is then decoded on the thread that reads it, at that thread's priority (the loop's
        feeder runs below the model's), and with less CPU than frame threading takes."""
        if decode_threads < 0:
            raise ValueError(f"decode_threads must be >= 0, got {decode_threads}")
        super().__init__(clock, wait)
        self.path = Path(path)
        self.cap = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG, [cv2.CAP_PROP_N_THREADS, decode_threads])
        if not self.cap.isOpened():          # a file FFmpeg does not read: whichever backend can
            self.cap = cv2.VideoCapture(str(self.path))
        if not self.cap.isOpened():
            raise ValueError(f"{self.path}: OpenCV cannot open this video")
        self.fps = self.cap.get(cv2.CAP_PROP_FPS) or 10.0
        count = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.total = count if count > 0 else None        # a stream of pictures says -2**63: not known
        self.size = capture_size(self.cap)
        self.packets = as_packets(self.cap)
        self.picture = self.path if is_image(self.path) else None
        self.pace, self.give_up = pace, give_up
        self.skipped = 0                 # frames the decoder jumped over or could not decode

    def _index_of_frame_read(self, expected: int) -> int:
        """The index of the frame just read, from its timestamp (``expected`` when there is none)."""
        ms = self.cap.get(cv2.CAP_PROP_POS_MSEC)
        if ms is None or ms <= 0:
            return expected
        return max(expected, round(ms * self.fps / 1000.0))

    def _frames(self) -> Iterator[Captured]:
        i = 0            # the index the next frame should have
        failures = 0     # failed reads since the last frame
        while not self.stopped:
            t0 = time.perf_counter()
            ok, frame = read_frame(self.cap, self.packets)
            dt = time.perf_counter() - t0
            if not ok:
                failures += 1
                if (self.total is not None and i + failures > self.total) or failures > self.give_up \
                        or (self.total is None and failures > 1):
                    self._end(i)
                    return
                continue
            k = self._index_of_frame_read(i)
            for j in range(i, k):          # skipped: by the decoder's jump, or by reads that failed
                self.skipped += 1
                yield Captured(j / self.fps, None, j, 0.0)
            failures = 0
            yield Captured(k / self.fps, frame, k, dt)
            i = k + 1

    def _release(self) -> None:
        self.cap.release()

    def _end(self, i: int) -> None:
        """The reads have stopped at index ``i``: the file's end, or frames before its end that do not
        decode (a failure; a file of unknown length ends at its first failed read)."""
        if self.total is None or i >= self.total:
            return
        self.skipped += self.total - i
        self.unread = self.total - i
        self.failure = (f"{self.path}: no frame decodes after frame {i - 1}; {self.total - i} of {self.total} "
                        "frames unread")


class ImageFolderSource(Source):
    def __init__(self, folder: str | Path, fps: float = 10.0, pace: bool = False,
                 clock: Callable[[], float] = time.monotonic, wait: Callable[[float], bool] | None = None) -> None:
        super().__init__(clock, wait)
        self.pace = pace
        self.folder = Path(folder)
        rgb = SequenceFolder(self.folder).dir(SequenceFolder.RGB)
        root = rgb if rgb.is_dir() else self.folder
        self.files = sorted(p for p in root.iterdir() if p.suffix.lower() in IMAGE_EXTS)
        if not self.files:
            raise ValueError(f"{self.folder}: no images ({', '.join(IMAGE_EXTS)})")
        self.fps = fps
        self.total = len(self.files)
        self.picture = self._typical(self.files[:SIZE_FROM])
        first = self._read(self.picture)               # as the frames are read: EXIF rotation applied
        self.size = None if first is None else (first.shape[1], first.shape[0])
        self.cameras = judge_folder(self.files, read=self._read)

    def _frames(self) -> Iterator[Captured]:
        for i, p in enumerate(self.files):
            t0 = time.perf_counter()
            frame = self._read(p)
            yield Captured(i / self.fps, frame, i, time.perf_counter() - t0, p.stem, p)

    @staticmethod
    def _typical(files: list[Path]) -> Path:
        """The first of ``files`` whose declared size is the commonest among them: the folder's size is
        most of its first pictures', not the first one's (an odd picture sorted first is one counted
        frame, not every frame after it)."""
        sizes = {}
        for p in files:
            try:
                sizes[p] = declared_size(read_user_file(p, "picture", head=HEADER_BYTES))
            except (OSError, ValueError):      # a FIFO or device named like a picture is no picture
                sizes[p] = None
        counts = Counter(s for s in sizes.values() if within_budget(s))
        if not counts:
            return files[0]
        common = counts.most_common(1)[0][0]
        return next(p for p in files if sizes[p] == common)

    @staticmethod
    def _read(path: Path) -> np.ndarray | None:
        """The picture, or None when it cannot be read whole: a header that cannot be read or that
        declares more than the pixel budget (checked before anything is decoded), or a cut file (which
        decodes with its missing part filled in: not a frame to run)."""
        try:
            data = read_user_file(path, "picture")
        except (OSError, ValueError):          # a FIFO, a device or a file over the budget: not a frame
            return None
        if not within_budget(declared_size(data)) or picture_damage(data, path.suffix) is not None:
            return None
        try:
            return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)  # EXIF rotation applied, as imread
        except cv2.error:                # a decoder that refuses what the header let through
            return None


def open_source(spec: str, pace: bool = False, fps: float = 10.0, decode_threads: int = 1,
                reconnect: Reconnect | None = None) -> Source:
    """``VIDEO`` file, image ``DIR``, camera index (``0``), or stream ``URL`` (``rtsp://...``); a camera
    or stream is watched and brought back as ``reconnect`` says (the vehicle file's ``[source]``; by default
    :class:`Reconnect`'s). ``decode_threads``: a video file's (:class:`VideoFileSource`)."""
    from bsn_edge.runtime.live_source import LiveSource, Reconnect

    policy = reconnect or Reconnect()
    if spec.isdigit():
        return LiveSource(int(spec), policy)
    if "://" in spec:
        return LiveSource(spec, policy)
    p = Path(spec)
    if p.is_dir():
        return ImageFolderSource(p, fps, pace)
    if p.is_file():
        return VideoFileSource(p, pace, decode_threads=decode_threads)
    raise FileNotFoundError(f"source {spec!r} is not a file, a folder, a camera index or a URL")
