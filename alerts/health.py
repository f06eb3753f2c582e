"""System state: OK, DEGRADED (too slow), UNAVAILABLE (no valid inference lately), and fault counters."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from enum import IntEnum


class SystemState(IntEnum):
    OK = 0
    DEGRADED = 1
    UNAVAILABLE = 2


FAULTS = ("decode_errors", "size_changes", "nan_outputs", "dropped_frames", "tx_errors", "tx_full",
          "serial_errors")


@dataclass(frozen=True)
class HealthConfig:
    deadline_s: float = 0.5     # no valid inference for longer: UNAVAILABLE
    fps_floor: float = 8.0      # valid inferences per second under this: DEGRADED
    window_s: float = 2.0       # over this window

    def __post_init__(self) -> None:
        if self.deadline_s <= 0 or self.fps_floor < 0 or self.window_s <= 0:
            raise ValueError("deadline_s and window_s must be positive, fps_floor >= 0")


@dataclass
class Health:
    """Pure: the caller reports valid inferences and faults with timestamps and asks for the state."""

    cfg: HealthConfig = field(default_factory=HealthConfig)
    faults: dict[str, int] = field(default_factory=lambda: dict.fromkeys(FAULTS, 0))
    _valid: deque = field(default_factory=deque)

    def valid(self, t: float) -> None:
        self._valid.append(t)
        while self._valid and self._valid[0] < t - self.cfg.window_s:
            self._valid.popleft()

    def fault(self, name: str, n: int = 1) -> None:
        if name not in self.faults:
            raise KeyError(f"unknown fault {name!r}; known: {', '.join(self.faults)}")
        self.faults[name] += n

    def fps(self, t: float) -> float:
        recent = [v for v in self._valid if v >= t - self.cfg.window_s]
        if len(recent) < 2:
            return 0.0
        span = max(t - recent[0], 1e-6)
        return (len(recent) - 1) / span if span < self.cfg.window_s else len(recent) / self.cfg.window_s

    def state(self, t: float) -> SystemState:
        if not self._valid or t - self._valid[-1] > self.cfg.deadline_s:
            return SystemState.UNAVAILABLE
        if self.fps(t) < self.cfg.fps_floor:
            return SystemState.DEGRADED
        return SystemState.OK
