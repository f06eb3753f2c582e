"""The terminating signals of a car-side command: what ends a run cleanly, and the exit code it ends with.

Only the standard library: a command installs these before it imports anything slow, so a signal at any
moment of its start-up is handled.
"""

from __future__ import annotations

import os
import signal
import threading
from typing import Any

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGINT", "SIGHUP", "SIGQUIT")
                     if hasattr(signal, name))


class _Arrivals:
    """The order the terminating signals arrived in. Python runs its handlers in the order of the signals'
    numbers, not of their arrival (a TERM then an INT at once would run INT's handler first); the C-level
    handler writes each signal's number to the wakeup pipe as it arrives, so the pipe knows. One per
    process (there is one wakeup descriptor), set up from the main thread."""

    def __init__(self) -> None:
        self.read_fd, write_fd = os.pipe()
        os.set_blocking(self.read_fd, False)
        os.set_blocking(write_fd, False)
        self.write_fd = write_fd
        self.old_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        self.held: list[int] = []        # signals caught before a StopOnSignal took over (hold_signals)

    def first(self, fallback: int) -> int:
        """The first terminating signal the pipe holds (``fallback`` when it holds none); the pipe is emptied."""
        data = b""
        try:
            while chunk := os.read(self.read_fd, 4096):
                data += chunk
        except BlockingIOError:
            pass
        return next((b for b in data if b in STOP_SIGNALS), fallback)

    def close(self) -> None:
        signal.set_wakeup_fd(self.old_fd)
        for fd in (self.read_fd, self.write_fd):
            os.close(fd)


_arrivals: _Arrivals | None = None


def _hold(signum: int, _frame: Any) -> None:
    if _arrivals is not None:
        _arrivals.held.append(signum)


def hold_signals() -> None:
    """Catch the terminating signals from a command's first instruction, before its modules are imported
    (they take a while), for the :class:`StopOnSignal` its ``main`` enters to act on: a signal during the
    imports then ends the run cleanly instead of by the default action. Main thread only."""
    global _arrivals
    if _arrivals is None:
        _arrivals = _Arrivals()
    for sig in STOP_SIGNALS:
        signal.signal(sig, _hold)


def exit_code(signame: str | None) -> int:
    """The exit code of a run a signal ended: 0 for SIGTERM (a service manager's stop), 128 + N for the
    others (130 SIGINT, 129 SIGHUP, 131 SIGQUIT)."""
    if signame is None or signame == "SIGTERM":
        return 0
    return 128 + int(signal.Signals[signame])


class StopOnSignal:
    """The terminating signals (TERM, as a service manager stops a process; INT, HUP when the terminal
    or SSH session closes; QUIT) all end the run cleanly: the loop finishes its frame, logs are closed,
    the summary is written, UNAVAILABLE is sent. The first signal names the stop; any after it change
    nothing (they are counted). ``keep``: once a signal came, the signals are ignored after the run, so
    a late one cannot kill the process while it writes its last words or shuts down (the command line);
    in a program that calls :func:`main` itself the handlers it had come back."""

    def __init__(self, source=None, keep: bool = False) -> None:
        self.source, self.event = source, threading.Event()
        self.signal: str | None = None
        self.later = 0
        self.keep = keep
        self._old: dict[int, Any] = {}

    def _handle(self, signum, _frame) -> None:
        if self.event.is_set():
            self.later += 1
            return
        if _arrivals is not None:            # the first to arrive, which is not always the first handled
            signum = _arrivals.first(signum)
        self.signal = signal.Signals(signum).name
        self.event.set()
        if self.source is not None:
            self.source.stop()

    def watch(self, source) -> None:
        """The source to stop on a signal (start-up is watched before there is one)."""
        self.source = source
        if self.event.is_set():
            source.stop()

    def __enter__(self) -> StopOnSignal:
        global _arrivals
        if threading.current_thread() is threading.main_thread():
            if _arrivals is None:
                _arrivals = _Arrivals()
            for sig in STOP_SIGNALS:
                old = signal.signal(sig, self._handle)
                self._old[sig] = signal.SIG_DFL if old is _hold else old
            held, _arrivals.held = _arrivals.held, []
            for signum in held:              # caught while the command started (hold_signals)
                self._handle(signum, None)
        return self

    def __exit__(self, *exc) -> None:
        global _arrivals
        if self.keep and self.event.is_set():
            # ignored, not handled: Python puts back the default action of the signals it handles while it
            # shuts down, and a late signal would then kill the process after its clean stop
            for sig in self._old:
                signal.signal(sig, signal.SIG_IGN)
        else:
            for sig, old in self._old.items():
                signal.signal(sig, old)
        if self._old and _arrivals is not None:
            _arrivals.close()
            _arrivals = None

