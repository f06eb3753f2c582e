"""The terminating signals of a car-side command: what ends a run cleanly, and the exit code it ends with.

Only the standard library: a command installs these before it imports anything slow, so a signal at any
moment of its start-up is handled.
"""

from __future__ import annotations

import signal
import threading
from typing import Any

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGINT", "SIGHUP", "SIGQUIT")
                     if hasattr(signal, name))


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
        if threading.current_thread() is threading.main_thread():
            for sig in STOP_SIGNALS:
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        if self.keep and self.event.is_set():
            # ignored, not handled: Python puts back the default action of the signals it handles while it
            # shuts down, and a late signal would then kill the process after its clean stop
            for sig in self._old:
                signal.signal(sig, signal.SIG_IGN)
            return
        for sig, old in self._old.items():
            signal.signal(sig, old)

