"""System state: OK, DEGRADED (too slow, an output down, a sector the camera cannot see), UNAVAILABLE (no
valid inference lately, or a camera that cannot see as a whole), CALIBRATING (the
camera's mounting is still being estimated: the sectors are not to be trusted yet), and fault counters.

Shared between the frame loop (which reports valid inferences and faults) and the heartbeat
thread (which asks for the state and the counters every cycle): every method takes the lock.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from enum import IntEnum, StrEnum

from bsn_edge.alerts.blindness import WHOLE, Blindness
from bsn_edge.config_toml import check_fields, setting


class SystemState(IntEnum):
    OK = 0
    DEGRADED = 1
    UNAVAILABLE = 2
    CALIBRATING = 3


class Fault(StrEnum):
    """The fault counters: what the loop, the send cycle and the senders count, the status message
    carries (``can_codec``) and the summary reports (by these names)."""

    DECODE_ERRORS = "decode_errors"          # a frame that would not decode
    SIZE_CHANGES = "size_changes"            # a frame of another size than the source's (not run)
    NAN_OUTPUTS = "nan_outputs"              # the model answered NaN or infinity
    DROPPED_FRAMES = "dropped_frames"        # a live source's frames the loop was too busy to take
    TX_ERRORS = "tx_errors"                  # a CAN send that failed
    TX_FULL = "tx_full"                      # the CAN transmit buffer was full
    SERIAL_ERRORS = "serial_errors"          # a serial write that failed
    SOURCE_RECONNECTS = "source_reconnects"  # a camera or stream reopened
    HEARTBEAT_ERRORS = "heartbeat_errors"    # an exception in the heartbeat thread
    SINK_ERRORS = "sink_errors"              # an output beside the bus (logs, overlay, maps) that failed
    UNSIGNED_MODEL = "unsigned_model"        # 1: the model is not signed by a trusted key (run by --allow-unsigned)


FAULTS = tuple(Fault)
# faults that degrade the system for the rest of the run, whatever the frame rate
DEGRADING = (Fault.SINK_ERRORS,)


@dataclass(frozen=True)
class Status:
    """The system's word at one send cycle (``BSN_Status``): decided once, by the send cycle, from
    :meth:`Health.snapshot`; the frame log and the overlay show the one that went on the bus."""

    state: SystemState
    fps: float                                   # valid inferences a second on the processing clock
    faults: dict[str, int] = field(default_factory=dict)     # the counters, by :class:`Fault`'s names
    camera: Blindness = Blindness.CLEAR          # why the camera cannot see (CLEAR: it can)
    why: str = ""                                # why the state is not OK, in words (not on the bus)


@dataclass(frozen=True)
class HealthConfig:
    deadline_s: float = setting(0.5, 0.05, 1.0, "s")          # no valid inference for longer: UNAVAILABLE
    fps_floor: float = setting(8.0, 0.0, 60.0, "frames/s")    # valid inferences per second under this: DEGRADED
    window_s: float = setting(2.0, 0.5, 10.0, "s")            # over this window

    def __post_init__(self) -> None:
        check_fields(self)


class Health:
    """Pure (time comes from the caller) and thread-safe: report valid inferences and faults with
    timestamps, ask for the state. ``unavailable()`` forces UNAVAILABLE from then on (the source
    ended or failed: no valid inference is coming).

    Two clocks: ``t`` is the frames' time, ``wall`` the processing clock, over which the frame rate is
    counted (the deadline is kept in both): a video file played faster or slower than it was
    recorded reports the rate the runtime achieves, not the file's. Without ``wall`` both are ``t``
    (a live camera, whose frame times are the processing clock)."""

    def __init__(self, cfg: HealthConfig | None = None) -> None:
        self.cfg = cfg or HealthConfig()
        self._faults: dict[Fault, int] = dict.fromkeys(FAULTS, 0)
        self._valid: deque[float] = deque()
        self._work: deque[float] = deque()     # processing-clock times of the same inferences
        self._down = False
        self._calibrating = False
        self._senders_down: set[str] = set()
        self._camera = Blindness.CLEAR
        self._lock = threading.Lock()

    def calibrating(self, on: bool) -> None:
        """While on, a state that would be OK reads CALIBRATING (a fault still reads as the fault)."""
        with self._lock:
            self._calibrating = bool(on)

    def camera(self, reason: Blindness) -> None:
        """The camera-health check's word: a reason that blinds the whole picture reads UNAVAILABLE, one that
        blinds some sectors (PARTIAL) DEGRADED, until it says CLEAR again."""
        with self._lock:
            self._camera = Blindness(reason)

    def sender_down(self, name: str, down: bool) -> None:
        """A sender that has failed every send for a while (a serial port gone, a bus off) is down: the
        state reads DEGRADED while any is (the other buses still hear it); one that sends again is up."""
        with self._lock:
            (self._senders_down.add if down else self._senders_down.discard)(name)

    @property
    def senders_down(self) -> list[str]:
        with self._lock:
            return sorted(self._senders_down)

    def valid(self, t: float, wall: float | None = None) -> None:
        """A valid inference on the frame of time ``t``, finished at ``wall`` on the processing clock."""
        w = t if wall is None else wall
        with self._lock:
            self._valid.append(t)
            self._work.append(w)
            while self._valid and self._valid[0] < t - self.cfg.window_s:
                self._valid.popleft()
            while self._work and self._work[0] < w - self.cfg.window_s:
                self._work.popleft()

    def fault(self, name: Fault, n: int = 1) -> None:
        with self._lock:
            self._check(name)
            self._faults[name] += n

    def set_fault(self, name: Fault, n: int) -> None:
        """Set a counter that another part keeps (e.g. the source's dropped frames)."""
        with self._lock:
            self._check(name)
            self._faults[name] = n

    def _check(self, name: Fault) -> None:
        if name not in self._faults:
            raise KeyError(f"unknown fault {name!r}; known: {', '.join(self._faults)}")

    @property
    def faults(self) -> dict[Fault, int]:
        """A copy of the fault counters."""
        with self._lock:
            return dict(self._faults)

    def unavailable(self) -> None:
        with self._lock:
            self._down = True

    def fps(self, t: float, wall: float | None = None) -> float:
        """Valid inferences per second of the processing clock, over the last ``window_s``."""
        with self._lock:
            return self._fps(t if wall is None else wall)

    def _fps(self, wall: float) -> float:
        recent = [v for v in self._work if v >= wall - self.cfg.window_s]
        if len(recent) < 2:
            return 0.0
        span = max(wall - recent[0], 1e-6)
        return (len(recent) - 1) / span if span < self.cfg.window_s else len(recent) / self.cfg.window_s

    def _state(self, t: float, wall: float) -> SystemState:
        return self._judge(t, wall)[0]

    def _judge(self, t: float, wall: float) -> tuple[SystemState, str]:
        """The state and, when it is not OK, the first reason for it in words."""
        # precedence: a fault outranks calibrating (UNAVAILABLE > DEGRADED > CALIBRATING > OK), so a
        # fault while the camera is still being calibrated shows as the fault
        # the deadline holds on both clocks: a file's frame time stands still while the loop is stuck on a
        # frame, the processing clock does not
        if self._down:
            return SystemState.UNAVAILABLE, "the run ending"
        if not self._valid:
            return SystemState.UNAVAILABLE, "no valid inference yet"
        if t - self._valid[-1] > self.cfg.deadline_s or wall - self._work[-1] > self.cfg.deadline_s:
            return SystemState.UNAVAILABLE, "stall: no valid inference within health.deadline_s"
        if self._camera in WHOLE:
            return SystemState.UNAVAILABLE, f"camera {self._camera.name}"
        # the rate is judged once a floor's interval has passed since the first inference in the window:
        # before that even one inference is on time (the first frame of a run is not DEGRADED)
        judged = bool(self._work) and wall - self._work[0] >= 1.0 / max(self.cfg.fps_floor, 1e-9)
        slow = judged and self._fps(wall) < self.cfg.fps_floor
        if slow:
            return SystemState.DEGRADED, "frame rate under health.fps_floor"
        if self._senders_down:
            return SystemState.DEGRADED, "output down: " + ", ".join(sorted(self._senders_down))
        failed = [f.value for f in DEGRADING if self._faults[f]]
        if failed:
            return SystemState.DEGRADED, "faults: " + ", ".join(failed)
        if self._camera:
            return SystemState.DEGRADED, f"camera {self._camera.name}"
        if self._calibrating:
            return SystemState.CALIBRATING, "calibrating: levels from an assumed camera"
        return SystemState.OK, ""

    def state(self, t: float, wall: float | None = None) -> SystemState:
        with self._lock:
            return self._state(t, t if wall is None else wall)

    def snapshot(self, t: float, wall: float | None = None) -> Status:
        """The :class:`Status` at ``t`` (``wall`` on the processing clock): state, frame rate and a copy of
        the counters, read together."""
        w = t if wall is None else wall
        with self._lock:
            state, why = self._judge(t, w)
            return Status(state, self._fps(w), {str(f): n for f, n in self._faults.items()}, self._camera, why)
