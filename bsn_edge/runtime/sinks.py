"""Outputs beside the bus (the frame log, the overlay, the maps): :class:`GuardedSink`.

The driver still needs the alerts when a disk fills or turns read-only, so no output of these may
stop the loop. The first failure of a sink is a fault: it is counted (``sink_errors``, which turns
the status DEGRADED), the sink writes nothing more, and the run's summary says which sink failed,
at which frame and why. Which outputs are essential is decided at start-up: a sink that cannot be
opened refuses the run (the user asked for it); one that fails later degrades it.

An output that costs a frame's time (drawing and encoding the overlay, encoding the maps) is
written on a thread of its own, ``behind`` frames at most behind the loop. From a file every frame
is written (the loop waits when the sink is that far behind, but an output stuck in one write for
``GuardedSink.STUCK_AFTER_S`` is a fault, not a hang); from a camera the loop never waits:
a frame the sink has no room for is left out of that output and counted (``dropped``), which is not
a fault: the alerts had it.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass
class SinkFailure:
    """Where a sink stopped: the frame it could not write, and the error."""

    sink: str
    frame: int
    error: str


class GuardedSink:
    """Wraps one output's ``write`` and ``close``; after the first exception it only counts.

    ``on_fault`` is called once, at the first failure (the loop counts it into the health), on the
    thread that wrote. ``behind`` > 0: writes run on a thread of the sink's own, at most that many
    frames behind; ``drop_when_full``: then a frame with no room is dropped instead of waited for.
    Waiting for room, and closing, wait at most ``STUCK_AFTER_S`` for that thread: an output stuck in
    a write (a hung disk) is a failure, and the run goes on and ends (its alerts and its last word on
    the bus are not held up)."""

    STUCK_AFTER_S = 10.0

    def __init__(self, name: str, write: Callable[..., Any], close: Callable[[], Any] | None = None,
                 on_fault: Callable[[SinkFailure], None] | None = None, behind: int = 0,
                 drop_when_full: bool = False) -> None:
        if behind < 0:
            raise ValueError(f"behind must be >= 0, got {behind}")
        self.name, self._write, self._close, self.on_fault = name, write, close, on_fault
        self.drop_when_full = drop_when_full
        self._lock = threading.Lock()          # failure, written and dropped: the loop's thread and the sink's
        self._failure: SinkFailure | None = None
        self._written = 0
        self._dropped = 0
        self._closed = False
        self._stuck = False                    # a write found no room for STUCK_AFTER_S: the thread is hung
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None
        if behind:
            self._queue = queue.Queue(maxsize=behind)
            self._thread = threading.Thread(target=self._work, name=f"bsn-sink-{name}", daemon=True)
            self._thread.start()

    @property
    def ok(self) -> bool:
        with self._lock:
            return self._failure is None

    @property
    def failure(self) -> SinkFailure | None:
        with self._lock:
            return self._failure

    @property
    def written(self) -> int:
        with self._lock:
            return self._written

    @property
    def dropped(self) -> int:
        """Frames left out of this output because it was behind (a camera's frames only)."""
        with self._lock:
            return self._dropped

    def write(self, frame: int, *args: Any) -> bool:
        """Write one frame's output (or hand it to the sink's thread); False (and, the first time, a
        fault) when it cannot, or when a camera's frame found no room."""
        if not self.ok or self._closed:
            return False
        if self._queue is None:
            return self._do(frame, args)
        if not self.drop_when_full:
            try:
                self._queue.put((frame, args), timeout=self.STUCK_AFTER_S)
            except queue.Full:
                self._stuck = True
                if self.ok:
                    self._fail(frame, TimeoutError(f"no room for a frame after {self.STUCK_AFTER_S:g} s: the "
                                                   "output is stuck in a write; given up"))
                return False
            return True
        try:
            self._queue.put_nowait((frame, args))
        except queue.Full:
            with self._lock:
                self._dropped += 1
            return False
        return True

    def close(self, frame: int = -1) -> None:
        """Write what is queued and finish the output (idempotent); a failure to finish it is reported
        like a write's."""
        if self._closed:
            return
        self._closed = True
        if self._stuck:     # its thread is hung in a write: waiting for it again only holds up the end
            return
        if self._queue is not None and self._thread is not None:
            with contextlib.suppress(queue.Full):
                self._queue.put(None, timeout=self.STUCK_AFTER_S)
            self._thread.join(timeout=self.STUCK_AFTER_S)
            if self._thread.is_alive():
                if self.ok:
                    self._fail(frame, TimeoutError(f"still writing after {self.STUCK_AFTER_S:g} s; given up"))
                return
        if self._close is None:
            return
        try:
            self._close()
        except Exception as e:
            if self.ok:
                self._fail(frame, e)

    def _do(self, frame: int, args: tuple) -> bool:
        try:
            self._write(*args)
        except Exception as e:  # a full or read-only disk, an encoder error: the alerts go on
            self._fail(frame, e)
            return False
        with self._lock:
            self._written += 1
        return True

    def _work(self) -> None:
        assert self._queue is not None
        while (item := self._queue.get()) is not None:
            if self.ok:
                self._do(*item)

    def _fail(self, frame: int, e: Exception) -> None:
        failure = SinkFailure(self.name, frame, f"{type(e).__name__}: {e}")
        with self._lock:
            self._failure = failure
        if self.on_fault is not None:
            self.on_fault(failure)


class LineLog:
    """A JSON-lines file that never ends in half a line: each record is written whole with ``os.write``,
    and a write that fails part-way (a full disk) is cut back to the end of the last whole line before
    the error is raised, so a reader of the file finds only whole records."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._end = 0

    def write(self, record: dict[str, Any]) -> None:
        data = (json.dumps(record) + "\n").encode()
        done = 0
        try:
            while done < len(data):
                done += os.write(self._fd, data[done:])
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self._end)
                os.lseek(self._fd, self._end, os.SEEK_SET)
            raise
        self._end += len(data)

    def close(self) -> None:
        """Idempotent."""
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)
