"""Outputs beside the bus (the frame log, the overlay, the maps): :class:`GuardedSink`.

The driver still needs the alerts when a disk fills or turns read-only, so no output of these may
stop the loop. The first failure of a sink is a fault: it is counted (``sink_errors``, which turns
the status DEGRADED), the sink writes nothing more, and the run's summary says which sink failed,
at which frame and why. Which outputs are essential is decided at start-up: a sink that cannot be
opened refuses the run (the user asked for it); one that fails later degrades it.
"""

from __future__ import annotations

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

    ``on_fault`` is called once, at the first failure (the loop counts it into the health)."""

    def __init__(self, name: str, write: Callable[..., Any], close: Callable[[], Any] | None = None,
                 on_fault: Callable[[SinkFailure], None] | None = None) -> None:
        self.name, self._write, self._close, self.on_fault = name, write, close, on_fault
        self.failure: SinkFailure | None = None
        self.written = 0
        self._closed = False

    @property
    def ok(self) -> bool:
        return self.failure is None

    def write(self, frame: int, *args: Any) -> bool:
        """Write one frame's output; False (and, the first time, a fault) when it cannot."""
        if self.failure is not None or self._closed:
            return False
        try:
            self._write(*args)
        except Exception as e:  # a full or read-only disk, an encoder error: the alerts go on
            self._fail(frame, e)
            return False
        self.written += 1
        return True

    def close(self, frame: int = -1) -> None:
        """Finish the output (idempotent); a failure to finish it is reported like a write's."""
        if self._closed:
            return
        self._closed = True
        if self._close is None:
            return
        try:
            self._close()
        except Exception as e:
            if self.failure is None:
                self._fail(frame, e)

    def _fail(self, frame: int, e: Exception) -> None:
        self.failure = SinkFailure(self.name, frame, f"{type(e).__name__}: {e}")
        if self.on_fault is not None:
            self.on_fault(self.failure)
