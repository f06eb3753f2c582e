"""What the runtime sends each cycle: per-sector hazard and the system's health."""

from __future__ import annotations

from dataclasses import dataclass, field

from bsn_edge.alerts.health import SystemState
from bsn_edge.alerts.state_machine import Level


@dataclass(frozen=True)
class SectorAlert:
    score: float            # smoothed, [0, 1]
    level: Level
    distance_m: float | None


@dataclass(frozen=True)
class AlertFrame:
    """One cycle's content; senders encode it, listeners decode it back."""

    t: float
    left: SectorAlert
    centre: SectorAlert
    right: SectorAlert
    state: SystemState
    fps: float
    faults: dict[str, int] = field(default_factory=dict)

    @property
    def sectors(self) -> tuple[SectorAlert, SectorAlert, SectorAlert]:
        return self.left, self.centre, self.right

    @classmethod
    def unavailable(cls, t: float, faults: dict[str, int] | None = None) -> AlertFrame:
        none = SectorAlert(0.0, Level.NONE, None)
        return cls(t, none, none, none, SystemState.UNAVAILABLE, 0.0, dict(faults or {}))
