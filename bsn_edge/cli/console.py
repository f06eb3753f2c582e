"""Standard output and error that cannot stop a run: a full disk under a redirected log, a closed pipe, a
terminal that went away. What could not be written is lost and said in the summary; the frames, the bus and
the summary go on. Only the standard library: ``bsn-run`` installs these before it imports anything slow."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TextIO


class ConsoleStream:
    """``stream`` whose writes and flushes never raise. The first that fails points the stream's descriptor
    at the null device (what is still buffered, flushed again when Python exits, would fail again and end
    the process with 120) and from then on the text is counted, not written."""

    def __init__(self, stream: TextIO, name: str) -> None:
        self.stream, self.name = stream, name
        self.failure: str | None = None
        self.lost_chars = 0

    def write(self, text: str) -> int:
        if self.failure is None:
            try:
                return self.stream.write(text)
            except (OSError, ValueError) as e:       # ValueError: written after it was closed
                self._lose(e)
        self.lost_chars += len(text)
        return len(text)

    def flush(self) -> None:
        if self.failure is None:
            try:
                self.stream.flush()
            except (OSError, ValueError) as e:
                self._lose(e)

    def _lose(self, error: Exception) -> None:
        self.failure = getattr(error, "strerror", None) or str(error) or type(error).__name__
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(null, self.stream.fileno())
            finally:
                os.close(null)
            self.stream.flush()
        except (OSError, ValueError, AttributeError):   # no descriptor (a test's capture): nothing to point
            pass

    def __getattr__(self, name: str) -> Any:             # isatty, fileno, encoding... as the stream has them
        return getattr(self.stream, name)


@contextmanager
def console_streams(keep: bool = False) -> Iterator[dict[str, ConsoleStream]]:
    """``sys.stdout`` and ``sys.stderr`` as :class:`ConsoleStream` for the block (``keep``: left in place after
    it, for a command line whose process ends next and flushes them on its way out). Yields them by name."""
    old = sys.stdout, sys.stderr
    streams = {"stdout": ConsoleStream(sys.stdout, "stdout"), "stderr": ConsoleStream(sys.stderr, "stderr")}
    sys.stdout, sys.stderr = streams["stdout"], streams["stderr"]
    try:
        yield streams
    finally:
        if not keep:
            sys.stdout, sys.stderr = old


def lost(streams: dict[str, ConsoleStream]) -> dict[str, dict[str, Any]]:
    """What could not be written, by stream (empty when everything was): for the summary."""
    return {name: {"error": s.failure, "lost_chars": s.lost_chars} for name, s in streams.items()
            if s.failure is not None}
