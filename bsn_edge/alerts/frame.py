"""What the runtime sends each cycle: per-sector hazard and the system's health."""

from __future__ import annotations

from dataclasses import dataclass, field

from bsn_edge.alerts.health import SystemState
from bsn_edge.alerts.sectors import SECTORS
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
    sectors: tuple[SectorAlert, ...]     # one per sector of ``SECTORS``, in its order
    state: SystemState
    fps: float
    faults: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if len(self.sectors) != len(SECTORS):
            raise ValueError(f"an alert frame has one reading per sector {SECTORS}, got {len(self.sectors)}")

    @classmethod
    def unavailable(cls, t: float, faults: dict[str, int] | None = None) -> AlertFrame:
        none = SectorAlert(0.0, Level.NONE, None)
        return cls(t, (none,) * len(SECTORS), SystemState.UNAVAILABLE, 0.0, dict(faults or {}))
