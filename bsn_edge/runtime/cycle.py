"""Sending at a fixed cycle, whatever the frame rate: the hazard and the status heartbeat."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable

from bsn_edge.alerts.bus_config import BusConfig, MessageRates
from bsn_edge.alerts.can_codec import HAZARD
from bsn_edge.alerts.frame import AlertFrame, Hazard
from bsn_edge.alerts.health import Fault, Health
from bsn_edge.alerts.senders import Sender


class CycleEmitter:
    """Sends the latest hazard the loop published, with the status of the cycle, to every sender at each
    cycle boundary up to ``t``.

    The status (state, frame rate and fault counters) is decided here, once per cycle, at ``t`` itself, so a
    stalled pipeline shows up as UNAVAILABLE on the bus within one cycle past the deadline; :meth:`last_sent`
    is the cycle as it went out, what the frame log and the overlay show. The faults each sender reports
    (:class:`~bsn_edge.alerts.senders.Sent`) are counted into the health's fault counters, which the next
    status message carries; a sender whose
    every send has failed for ``down_after_s`` is down (DEGRADED) until one goes through. Each message
    goes every so many cycles (``rates``, the vehicle file's ``[messages]``).
    """

    def __init__(self, senders: list[Sender], health: Health, cycle_s: float = 0.1,
                 clock: Callable[[], float] | None = None, rates: MessageRates | None = None,
                 down_after_s: float = BusConfig.down_after_s) -> None:
        """``clock`` is the processing clock the frame rate is counted on when the cycle times are a
        file's (see :class:`Health`); None when they are the processing clock already (live). ``rates``:
        each message every so many cycles (all every cycle by default); ``down_after_s``: how long every
        send of a sender may fail before it is down."""
        if cycle_s <= 0:
            raise ValueError(f"cycle must be positive, got {cycle_s}")
        self.senders, self.health, self.cycle_s, self.clock = senders, health, cycle_s, clock
        self.rates = rates or MessageRates()
        self.rates.check(cycle_s)
        self.down_after_s = down_after_s
        self.ticks = 0                  # cycles of the schedule sent: which messages are due
        self.latest: Hazard | None = None
        self.hazards_sent = 0           # cycles that carried the hazard message: its frames' number on a bus
        self.latest_from = 0            # the number of the first hazard frame that carries ``latest``
        self._last: AlertFrame | None = None       # the last cycle as it went out
        self.next_t: float | None = None
        self.sent_cycles = 0
        self.stall_cycles = 0           # of them, sent by the stall watch while the loop was stuck on a frame
        self.state_cycles: dict[str, int] = {}     # cycles sent in each state, by its name (the last word apart)
        self.why_cycles: dict[str, dict[str, int]] = {}     # of them, by state and the reason for it
        self.last_sent_at: float | None = None     # on ``clock``, when there is one
        self.stalling = False           # the last cycle was the stall watch's
        self._failing_since: dict[str, float] = {}     # a sender's first failed send of its current run
        self._lock = threading.Lock()

    def publish(self, hazard: Hazard) -> None:
        """The loop's latest word on the sectors, for the cycles to come; :attr:`latest_from` is the number
        (from 0, among the hazard frames sent) of the first that carries it."""
        with self._lock:
            self.latest = hazard
            self.latest_from = self.hazards_sent

    def last_sent(self) -> AlertFrame | None:
        """The last cycle as it went out (None before the first)."""
        with self._lock:
            return self._last

    def emit(self, t: float) -> int:
        """Send every cycle due by ``t``; returns how many."""
        with self._lock:
            if self.next_t is None:
                self.next_t = t
            n = 0
            while self.next_t <= t + 1e-9:
                self._send(self.next_t, self._due())
                self.next_t += self.cycle_s
                self.ticks += 1
                n += 1
            self.stalling = self.stalling and n == 0
            return n

    def _due(self) -> tuple[str, ...]:
        """The messages due at this cycle of the schedule (every one at the first)."""
        return tuple(name for name, every in self.rates.every().items() if self.ticks % every == 0)

    def overdue(self, after_s: float) -> bool:
        """Whether no cycle has gone out for ``after_s`` of the processing clock, or for a cycle once the
        stall watch has begun sending (none yet counts from the first time this is asked); always False
        without a processing clock."""
        if self.clock is None:
            return False
        now = self.clock()
        with self._lock:
            if self.last_sent_at is None:
                self.last_sent_at = now
            return now - self.last_sent_at >= (self.cycle_s if self.stalling else after_s)

    def stalled(self) -> None:
        """Send one cycle now, while the frames' time stands still (the loop is stuck on a frame): stamped
        at the last cycle's time, its state read at the processing clock's now, so it says UNAVAILABLE once
        the deadline has passed there since the last valid inference. The schedule is not moved."""
        with self._lock:
            t = self.next_t - self.cycle_s if self.next_t is not None else 0.0
            self._send(t)
            self.stall_cycles += 1
            self.stalling = True

    def final(self, t: float) -> None:
        """Send one more cycle at ``t`` now, whatever the schedule (the run is ending: the health
        has been marked unavailable, so this says UNAVAILABLE on every bus)."""
        with self._lock:
            self._send(t, last_word=True)

    def _send(self, t: float, messages: tuple[str, ...] | None = None, last_word: bool = False) -> None:
        """Send ``messages`` (every one by default: a stall's or the last word) of the frame at ``t``; the
        last word is not counted in :attr:`state_cycles` (every run ends UNAVAILABLE: that is no time the
        bus spent in the state while the run lived)."""
        h = self.health
        status = h.snapshot(t) if self.clock is None else h.snapshot(t, self.clock())
        frame = AlertFrame.of(t, self.latest if self.latest is not None else Hazard.none(t), status)
        for s in self.senders:
            sent = s.send(frame, messages)
            if sent.ok:
                self._failing_since.pop(s.name, None)
                h.sender_down(s.name, False)
            elif t - self._failing_since.setdefault(s.name, t) >= self.down_after_s:
                h.sender_down(s.name, True)
            for fault, n in sent.faults.items():
                h.fault(fault, n)
        self._last = frame
        self.sent_cycles += 1
        self.hazards_sent += messages is None or HAZARD in messages
        if not last_word:
            self.state_cycles[frame.state.name] = self.state_cycles.get(frame.state.name, 0) + 1
            if status.why:
                why = self.why_cycles.setdefault(frame.state.name, {})
                why[status.why] = why.get(status.why, 0) + 1
        if self.clock is not None:
            self.last_sent_at = self.clock()


class Heartbeat:
    """A thread that drives a CycleEmitter on the wall clock (live sources). It survives any
    exception of a cycle: counted as ``heartbeat_errors`` (the next status carries it), then on.

    It wakes every half cycle (:attr:`WAKES_PER_CYCLE`), so a cycle goes out at most half a cycle
    late and no two go out further apart than one and a half cycles. ``wait(seconds)`` sleeps
    between wakes and says whether to stop; by default the wall clock's, a simulated one in tests."""

    WAKES_PER_CYCLE = 2

    def __init__(self, emitter: CycleEmitter, clock: Callable[[], float] = time.monotonic,
                 wait: Callable[[float], bool] | None = None) -> None:
        self.emitter, self.clock = emitter, clock
        self.last_error = ""
        self._stop = threading.Event()
        self._wait = wait if wait is not None else self._stop.wait
        self._thread = threading.Thread(target=self.run, name="bsn-heartbeat", daemon=True)

    def run(self) -> None:
        """The thread's loop (:meth:`start` runs it on its own thread): a beat, then a wait, until closed."""
        while not self._stop.is_set():
            try:
                self.beat()
            except Exception as e:  # the bus must never go silent while the loop runs
                self.last_error = f"{type(e).__name__}: {e}"
                with contextlib.suppress(Exception):   # nothing more to do than to go on
                    self.emitter.health.fault(Fault.HEARTBEAT_ERRORS)
            if self._wait(self.emitter.cycle_s / self.WAKES_PER_CYCLE):
                return

    def beat(self) -> None:
        """One wake's work: the cycles due by the wall clock's now."""
        self.emitter.emit(self.clock())

    def start(self) -> Heartbeat:
        """Start the thread; returns the heartbeat (``close()`` stops it)."""
        self._thread.start()
        return self

    def __enter__(self) -> Heartbeat:
        return self.start()

    def close(self) -> None:
        """Stop the thread (idempotent); the caller sends what comes after."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2)

    def __exit__(self, *exc) -> None:
        self.close()


class StallWatch(Heartbeat):
    """The heartbeat of a source whose frames carry their own times (a file or a folder), whose cycles the
    loop sends by those times: when none has gone out for ``after_s`` of the processing clock (the loop is
    stuck on a slow frame, a slow disk or a slow model), it sends one, then one every cycle until the loop
    sends again (:meth:`CycleEmitter.stalled`). The bus is never silent for longer than ``after_s`` and half
    a cycle (its wakes) while the run lives."""

    def __init__(self, emitter: CycleEmitter, after_s: float,
                 wait: Callable[[float], bool] | None = None) -> None:
        if emitter.clock is None:
            raise ValueError("a stall watch needs the emitter's processing clock")
        super().__init__(emitter, emitter.clock, wait)
        self.after_s = after_s

    def beat(self) -> None:
        if self.emitter.overdue(self.after_s):
            self.emitter.stalled()
