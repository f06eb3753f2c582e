"""Cameras and streams: :class:`LiveSource`, read on the wall clock by a thread that keeps only the newest
frame, watched for stalls and brought back as :class:`Reconnect` says."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import cv2

from bsn_edge.runtime.slot import LatestSlot
from bsn_edge.runtime.sources import Captured, Source, as_packets, capture_size, read_frame


@dataclass(frozen=True)
class Reconnect:
    """How a live source comes back: a read that delivers nothing for ``stall_s`` counts as
    lost; reopen after ``first_s``, doubling up to ``max_s`` between tries; give up after
    ``give_up_s`` without a frame (0: never) or after ``max_tries`` reopenings in a row (None: no
    limit; 0: the first loss ends the source, as for a file read as a camera)."""

    stall_s: float = 2.0
    first_s: float = 0.25
    max_s: float = 4.0
    give_up_s: float = 60.0
    max_tries: int | None = None

    def __post_init__(self) -> None:
        if not (self.stall_s > 0 and 0 < self.first_s <= self.max_s and self.give_up_s >= 0):
            raise ValueError("reconnect: stall_s, first_s > 0, first_s <= max_s, give_up_s >= 0")
        if self.max_tries is not None and self.max_tries < 0:
            raise ValueError("reconnect: max_tries must be >= 0 or None")


def open_capture(target: int | str, stall_s: float) -> cv2.VideoCapture:
    """A capture whose open and reads give up after ``stall_s``. Stream URLs go through FFmpeg with the
    timeouts passed at open, the one way its backend honours them (set after opening, a stalled read
    waits FFmpeg's default 30 s)."""
    if isinstance(target, str):
        ms = round(stall_s * 1000)
        return cv2.VideoCapture(target, cv2.CAP_FFMPEG, [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms,
                                                         cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms])
    return cv2.VideoCapture(target)


class LiveSource(Source):
    """A camera index or a stream URL, read by a thread that keeps only the newest frame.

    A source that fails or stalls is reopened with back-off (``Reconnect``), counted in
    ``reconnects``; meanwhile no frame comes, so the status goes UNAVAILABLE on the bus. After
    ``give_up_s`` without a frame the source has failed (``failure`` says why).
    """

    live = True

    def __init__(self, target: int | str, reconnect: Reconnect | None = None, opener=None) -> None:
        super().__init__()
        self.target, self.policy = target, reconnect or Reconnect()
        self._opener = opener or (lambda t: open_capture(t, self.policy.stall_s))
        self._packets = False
        self.cap = self._open()
        if self.cap is None:
            raise ValueError(f"cannot open camera or stream {target!r}")
        if hasattr(self.cap, "get"):
            self.fps = self.cap.get(cv2.CAP_PROP_FPS) or self.fps
            self.size = capture_size(self.cap)
        self._lock = threading.Lock()
        self._slot: LatestSlot[Captured] = LatestSlot(newest_wins=True)
        self._asked = False        # the loop has asked for a frame: from then on a replaced one is dropped
        self._last_frame = time.monotonic()
        self._ended = threading.Event()
        self._thread = threading.Thread(target=self._read, name="bsn-capture", daemon=True)
        self._thread.start()

    def _open(self):
        cap = self._opener(self.target)
        if not cap.isOpened():
            cap.release()
            return None
        self._packets = as_packets(cap)         # a reopened stream may come back in another format
        return cap

    def _reopen(self) -> bool:
        """Back-off reopening until a frame source is back, or give up."""
        delay = self.policy.first_s
        tries = 0
        while not self._stop.is_set():
            if self.policy.max_tries is not None and tries >= self.policy.max_tries:
                if self.policy.max_tries:
                    self.failure = f"camera or stream {self.target!r}: lost, and {tries} reconnects failed"
                return False
            if self.policy.give_up_s and time.monotonic() - self._last_frame > self.policy.give_up_s:
                self.failure = (f"camera or stream {self.target!r}: no frame for {self.policy.give_up_s:g} s "
                                f"after {self.reconnects} reconnects")
                return False
            tries += 1
            if self._stop.wait(delay):
                return False
            with self._lock:
                self.reconnects += 1
            if self.cap is not None:
                self.cap.release()
            self.cap = self._open()
            if self.cap is not None:
                return True
            delay = min(2 * delay, self.policy.max_s)
        return False

    def _read(self) -> None:
        i = 0
        while not self._stop.is_set():
            t0 = time.perf_counter()
            try:
                ok, frame = read_frame(self.cap, self._packets)
            except Exception:   # a backend that raises has lost the camera as one that returns nothing
                ok, frame = False, None
            dt = time.perf_counter() - t0
            if not ok or (frame is None and not self._packets) or dt > self.policy.stall_s:
                if not self._reopen():
                    self._ended.set()
                    self._slot.end()
                    return
                continue
            now = time.monotonic()
            with self._lock:
                self._last_frame = now
            _, replaced = self._slot.put(Captured(now, frame, i, dt))
            if replaced is not None:
                with self._lock:
                    if self._asked:
                        self.dropped += 1
                    else:
                        self.before_start += 1
            i += 1

    def _frames(self) -> Iterator[Captured]:
        with self._lock:
            self._asked = True
        while not self.stopped:
            item = self._slot.take(timeout=0.1)
            if item is not None:
                yield item
            elif self._ended.is_set() or self._slot.closed:
                return

    @property
    def last_frame_at(self) -> float:
        """``time.monotonic()`` when the newest frame was read (or the source opened)."""
        with self._lock:
            return self._last_frame

    def _on_stop(self) -> None:
        self._slot.close()

    def _release(self) -> None:
        self._thread.join(timeout=2)
        if self.cap is not None:
            self.cap.release()
