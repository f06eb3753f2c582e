"""What the runtime sends each cycle: per-sector hazard and the system's health.

Two records, each decided once by its owner: the loop's :class:`Hazard` (what the model saw in a frame, smoothed
per sector) and the send cycle's :class:`~bsn_edge.alerts.health.Status`; an :class:`AlertFrame` is the two at
one cycle, what the encoders put on a bus and the listeners read back.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from bsn_edge.alerts.blindness import WHOLE, Blindness
from bsn_edge.alerts.health import Status, SystemState
from bsn_edge.alerts.state_machine import Level


@dataclass(frozen=True)
class SectorAlert:
    score: float            # smoothed, [0, 1]
    level: Level
    distance_m: float | None
    unseen: bool = False    # the camera cannot see this sector: its level says nothing of it


@dataclass(frozen=True)
class Hazard:
    """The loop's word on one frame (``BSN_Hazard``): its time and one smoothed reading per sector."""

    t: float
    sectors: tuple[SectorAlert, ...]     # one per sector of the layout, left to right; () before the first frame

    @classmethod
    def none(cls, t: float, unseen: bool = False, count: int = 0) -> Hazard:
        """Nothing to warn of in ``count`` sectors: what goes with an UNAVAILABLE status, whatever the last frame
        saw (``unseen``: because the camera cannot see). With none (``count`` 0), the encoder says NONE in every
        sector of its layout."""
        return cls(t, (SectorAlert(0.0, Level.NONE, None, unseen),) * count)


@dataclass(frozen=True)
class AlertFrame:
    """One cycle's content (a :class:`Hazard` and a :class:`Status` at ``t``); senders encode it, listeners
    decode it back."""

    t: float
    sectors: tuple[SectorAlert, ...]     # one per sector of the layout, left to right; () for no hazard yet
    state: SystemState
    fps: float
    faults: dict[str, int] = field(default_factory=dict)
    camera: Blindness = Blindness.CLEAR
    why: str = ""                        # the status's reason in words: for the frame log, never encoded

    @classmethod
    def of(cls, t: float, hazard: Hazard, status: Status) -> AlertFrame:
        """The cycle at ``t`` carrying ``hazard`` and ``status``: an UNAVAILABLE status carries no hazard (every
        sector unseen when the camera cannot see as a whole)."""
        if status.state == SystemState.UNAVAILABLE:
            hazard = Hazard.none(t, status.camera in WHOLE, len(hazard.sectors))
        return cls(t, hazard.sectors, status.state, status.fps, dict(status.faults), status.camera, status.why)

    @classmethod
    def unavailable(cls, t: float, faults: dict[str, int] | None = None) -> AlertFrame:
        return cls.of(t, Hazard.none(t), Status(SystemState.UNAVAILABLE, 0.0, dict(faults or {})))

    @property
    def hazard(self) -> Hazard:
        return Hazard(self.t, self.sectors)

    @property
    def status(self) -> Status:
        return Status(self.state, self.fps, dict(self.faults), self.camera, self.why)
