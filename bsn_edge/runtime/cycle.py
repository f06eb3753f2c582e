"""Sending at a fixed cycle, whatever the frame rate: the hazard and the status heartbeat."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import replace

from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.health import Health, SystemState
from bsn_edge.alerts.senders import Sender


class CycleEmitter:
    """Sends the latest alert frame to every sender at each cycle boundary up to ``t``.

    The state, frame rate and fault counters are those of ``t`` itself, so a stalled pipeline
    shows up as UNAVAILABLE on the bus within one cycle past the deadline. Sender failures are
    counted into the health's fault counters, which the next status message carries.
    """

    def __init__(self, senders: list[Sender], health: Health, cycle_s: float = 0.1) -> None:
        if cycle_s <= 0:
            raise ValueError(f"cycle must be positive, got {cycle_s}")
        self.senders, self.health, self.cycle_s = senders, health, cycle_s
        self.latest: AlertFrame | None = None
        self.next_t: float | None = None
        self.sent_cycles = 0
        self._lock = threading.Lock()

    def publish(self, frame: AlertFrame) -> None:
        with self._lock:
            self.latest = frame

    def emit(self, t: float) -> int:
        """Send every cycle due by ``t``; returns how many."""
        with self._lock:
            if self.next_t is None:
                self.next_t = t
            n = 0
            while self.next_t <= t + 1e-9:
                self._send(self.next_t)
                self.next_t += self.cycle_s
                n += 1
            return n

    def _send(self, t: float) -> None:
        h = self.health
        state = h.state(t)
        base = self.latest if self.latest is not None and state != SystemState.UNAVAILABLE \
            else AlertFrame.unavailable(t)
        frame = replace(base, t=t, state=state, fps=h.fps(t), faults=dict(h.faults))
        for s in self.senders:
            before_err, before_full = s.stats.errors, s.stats.full
            s.send(frame)
            if s.stats.errors > before_err:
                h.fault("serial_errors" if s.name == "serial" else "tx_errors", s.stats.errors - before_err)
            if s.stats.full > before_full:
                h.fault("tx_full", s.stats.full - before_full)
        self.sent_cycles += 1


class Heartbeat:
    """A thread that drives a CycleEmitter on the wall clock (live sources)."""

    def __init__(self, emitter: CycleEmitter, clock: Callable[[], float] = time.monotonic) -> None:
        self.emitter, self.clock = emitter, clock
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bsn-heartbeat", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.emitter.emit(self.clock())
            self._stop.wait(self.emitter.cycle_s / 2)

    def __enter__(self) -> Heartbeat:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
