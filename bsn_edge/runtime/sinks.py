"""Outputs beside the bus (the frame log, the overlay, the maps): :class:`GuardedSink`.

The driver still needs the alerts when a disk fills, turns read-only or hangs, so no output of these
may stop the loop. Each output is opened, written and finished on a thread of its own, never on the
frame path. The first failure of a sink is a fault: it is counted (``sink_errors``, which turns the
status DEGRADED), the sink writes nothing more, and the run's summary says which sink failed, at which
frame and why. An output busy with one thing (opening it, one frame, finishing it) for
``GuardedSink.STUCK_AFTER_S`` is stuck, which is a failure like any other: a FIFO nobody reads, a hung
disk or network mount. Which outputs are essential is decided at start-up: one that refuses to open
within ``OPEN_WAIT_S`` refuses the run (the user asked for it); one still opening then is waited for
no longer, and fails if it stays stuck.

At most ``behind`` frames wait for a sink. From a file every frame is written (the loop waits for room,
but no longer than the sink may take before it counts as stuck); from a camera the loop never waits:
a frame the sink has no room for is left out of that output and counted (``dropped``), which is not a
fault: the alerts had it.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

OPEN_WAIT_S = 0.5      # how long start-up waits for its outputs to open before the first frame


@dataclass
class SinkFailure:
    """Where a sink stopped: the frame it could not write (None: it never opened), and the error."""

    sink: str
    frame: int | None
    error: str

    @property
    def where(self) -> str:
        """``at frame N`` or ``when it was opened``, for messages."""
        return "when it was opened" if self.frame is None else f"at frame {self.frame}"


class GuardedSink:
    """Wraps one output's ``open``, ``write`` and ``close``, all run on a thread of the sink's own;
    after the first exception it only counts.

    ``on_fault`` is called once, at the first failure (the loop counts it into the health). At most
    ``behind`` frames wait for the thread; ``drop_when_full``: a frame with no room is dropped instead
    of waited for. :meth:`check` (called by every :meth:`write`, and by the loop once a frame) turns an
    output busy with one thing for ``STUCK_AFTER_S`` into a failure; :meth:`close` waits for the thread
    no longer than that either (its alerts and its last word on the bus are not held up)."""

    STUCK_AFTER_S = 1.0

    def __init__(self, name: str, write: Callable[..., Any], close: Callable[[], Any] | None = None,
                 on_fault: Callable[[SinkFailure], None] | None = None, behind: int = 1,
                 drop_when_full: bool = False, open: Callable[[], Any] | None = None) -> None:
        if behind < 1:
            raise ValueError(f"behind must be >= 1, got {behind}")
        self.name, self._write, self._close, self._open, self.on_fault = name, write, close, open, on_fault
        self.drop_when_full = drop_when_full
        self._lock = threading.Lock()          # failure, counts and the busy clock: the loop's thread and the sink's
        self._failure: SinkFailure | None = None
        self._written = 0
        self._dropped = 0
        self._closed = False
        self._close_frame = -1
        self._busy_since: float | None = None  # when the sink's thread began what it is doing now
        self._busy_frame: int | None = None    # ... for which frame (None: opening it)
        self._busy_what = ""
        self._opened = threading.Event()       # opening is over, either way
        self._queue: queue.Queue = queue.Queue(maxsize=behind)
        if open is not None:
            self._set_busy(None, "opening it")
        else:
            self._opened.set()
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

    def wait_open(self, timeout: float) -> SinkFailure | None:
        """Wait up to ``timeout`` for the output to open; its failure if opening failed (None while it
        is still opening: :meth:`check` decides later whether it is stuck)."""
        self._opened.wait(timeout)
        return self.failure

    def check(self) -> bool:
        """Whether the sink is still writing; an output busy with one thing for ``STUCK_AFTER_S`` fails now."""
        if self._stuck():
            with self._lock:
                frame, what = self._busy_frame, self._busy_what
            self._fail(frame, TimeoutError(f"stuck in {what} for more than {self.STUCK_AFTER_S:g} s (a FIFO nobody "
                                           "reads, a hung disk or mount?); given up"))
        return self.ok

    def _stuck(self) -> bool:
        """Whether the sink's thread has been busy with one thing for longer than ``STUCK_AFTER_S``."""
        with self._lock:
            since = self._busy_since
        return since is not None and time.monotonic() - since > self.STUCK_AFTER_S

    def write(self, frame: int, *args: Any) -> bool:
        """Hand one frame's output to the sink's thread; False (and, the first time, a fault) when it
        cannot, or when a camera's frame found no room."""
        if self._closed or not self.check():
            return False
        if self.drop_when_full:
            try:
                self._queue.put_nowait((frame, args))
            except queue.Full:
                with self._lock:
                    self._dropped += 1
                return False
            return True
        while True:     # a file's frame waits for room, but never for an output that is stuck
            try:
                self._queue.put((frame, args), timeout=min(0.05, self.STUCK_AFTER_S))
                return True
            except queue.Full:
                if not self.check():
                    return False

    def close(self, frame: int = -1) -> None:
        """Write what is queued and finish the output on its thread (idempotent); a failure to finish it
        is reported like a write's. Waits only while the sink is not stuck."""
        if self._closed:
            return
        self._closed = True
        self._close_frame = frame
        while True:
            if self._stuck():
                self.check()
                return
            try:
                self._queue.put(None, timeout=0.05)
                break
            except queue.Full:
                continue
        while self._thread.is_alive():
            if self._stuck():
                self.check()
                return
            self._thread.join(timeout=0.05)

    def _set_busy(self, frame: int | None, what: str) -> None:
        with self._lock:
            self._busy_since, self._busy_frame, self._busy_what = time.monotonic(), frame, what

    def _idle(self) -> None:
        with self._lock:
            self._busy_since = self._busy_frame = None

    def _run(self, frame: int | None, what: str, fn: Callable[..., Any], *args: Any) -> bool:
        self._set_busy(frame, what)
        try:
            fn(*args)
        except Exception as e:  # a full or read-only disk, an encoder error: the alerts go on
            self._fail(frame, e)
            return False
        finally:
            self._idle()
        return True

    def _work(self) -> None:
        if self._open is not None:
            self._run(None, "opening it", self._open)
            self._opened.set()
        while (item := self._queue.get()) is not None:
            frame, args = item
            if self.ok and self._run(frame, "one write", self._write, *args):
                with self._lock:
                    self._written += 1
        if self._close is not None:      # after a failure too: what was opened is let go
            self._run(self._close_frame, "finishing it", self._close)

    def _fail(self, frame: int | None, e: BaseException) -> None:
        failure = SinkFailure(self.name, frame, f"{type(e).__name__}: {e}")
        with self._lock:
            if self._failure is not None:
                return
            self._failure = failure
        if self.on_fault is not None:
            self.on_fault(failure)


def open_all(sinks: Iterable[GuardedSink], timeout: float = OPEN_WAIT_S) -> None:
    """Wait (together, ``timeout`` at most) for outputs to open; ``OSError`` names the first that failed
    (the run is refused). One still opening is not waited for any longer."""
    deadline = time.monotonic() + timeout
    for sink in sinks:
        failure = sink.wait_open(max(0.0, deadline - time.monotonic()))
        if failure is not None:
            raise OSError(f"cannot open the {sink.name} output: {failure.error}")


class LineLog:
    """A JSON-lines file that never ends in half a line: each record is written whole with ``os.write``,
    and a write that fails part-way (a full disk) is cut back to the end of the last whole line before
    the error is raised, so a reader of the file finds only whole records."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = path
        self._fd = -1
        self._end = 0

    def open(self) -> None:
        """Create (or empty) the file; on the sink's thread, since opening may block (a FIFO, a hung mount)."""
        Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)

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
