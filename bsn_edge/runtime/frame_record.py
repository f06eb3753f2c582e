"""One line of the frame log (``bsn-run --log``): :class:`FrameRecord`.

Fields, in the order written (a field that does not apply to the frame is left out): ``frame`` (index in the
source), ``t`` (seconds on the source's clock), ``fault`` (what went wrong with this frame, by the names of
:class:`~bsn_edge.alerts.health.Fault`: ``decode_errors``, ``size_changes``, ``nan_outputs``), ``levels`` (one
per sector of the layout, left to right: ``NONE``, ``CAUTION`` or ``WARNING``; the run's summary names the
sectors, ``settings.sectors.layout``), ``scores`` (smoothed, 0-1), ``distances`` (metres to the nearest blind
spot, null for none), ``state`` (the system state the bus carried when the frame's hazard was made: the last
status sent) and ``why`` (the reason for a state other than OK, in words), ``camera`` and ``unseen`` (when the
camera-health check raised a reason: its name, and the sectors it cannot see), ``latency_ms`` and ``stage_ms``
(this frame's milliseconds in each stage it went through, :data:`~bsn_edge.runtime.stages.STAGES`),
``bus_from`` (the number, from 0 among the hazard frames sent, of the first that carried this frame's levels:
every hazard frame from it until the next frame's carries them, which lets ``bsn-report`` compare the bus
cycle by cycle).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from bsn_edge.alerts.blindness import Blindness
from bsn_edge.alerts.frame import Hazard, SectorAlert
from bsn_edge.alerts.health import Fault, Status, SystemState
from bsn_edge.alerts.sectors import SECTORS
from bsn_edge.alerts.state_machine import Level
from bsn_edge.runtime.visibility import Visibility


@dataclass
class FrameRecord:
    """What the loop knows of one frame, filled in stage by stage."""

    frame: int
    t: float
    fault: Fault | None = None
    hazard: Hazard | None = None        # the loop's word on this frame
    status: Status | None = None        # the bus's, at the last cycle sent (None before the first)
    latency_ms: float | None = None
    stage_ms: dict[str, float] = field(default_factory=dict)
    visibility: Visibility | None = None   # the camera-health check's word on this frame
    bus_from: int | None = None            # the first hazard frame on the bus that carries this frame's levels
    names: tuple[str, ...] = SECTORS       # the sectors of the layout, left to right (not written: the summary's)

    def to_json(self) -> dict[str, Any]:
        """The frame log's line (rounded as written)."""
        out: dict[str, Any] = {"frame": self.frame, "t": round(self.t, 4)}
        if self.fault is not None:
            out["fault"] = self.fault.value
        if self.hazard is not None:
            sectors = self.hazard.sectors
            out.update(levels=[s.level.name for s in sectors], scores=[round(s.score, 3) for s in sectors],
                       distances=[None if s.distance_m is None else round(s.distance_m, 2) for s in sectors])
            if self.status is not None:
                out["state"] = self.status.state.name
                if self.status.why:
                    out["why"] = self.status.why
            if self.bus_from is not None:
                out["bus_from"] = self.bus_from
        if self.visibility is not None and self.visibility.reason is not Blindness.CLEAR:
            out["camera"] = self.visibility.reason.name
            out["unseen"] = [s for s, u in zip(self.names, self.visibility.unseen, strict=True) if u]
        if self.latency_ms is not None:
            out["latency_ms"] = round(self.latency_ms, 2)
        if self.stage_ms:
            out["stage_ms"] = {k: round(v, 3) for k, v in self.stage_ms.items()}
        return out

    @classmethod
    def from_json(cls, d: dict[str, Any], names: tuple[str, ...] = SECTORS) -> FrameRecord:
        """A line of the frame log of a run whose sectors are ``names`` read back (``KeyError`` / ``ValueError``
        for one that is not a line of it, levels of another count included); the status's frame rate and
        counters, which the log does not keep, are 0 and empty."""
        rec = cls(int(d["frame"]), float(d["t"]), names=names)
        if "fault" in d:
            rec.fault = Fault(d["fault"])
        if "levels" in d:
            sectors = tuple(SectorAlert(float(s), Level[lv], None if m is None else float(m))
                            for lv, s, m in zip(d["levels"], d["scores"], d["distances"], strict=True))
            if len(sectors) != len(names):
                raise ValueError(f"{len(sectors)} levels for the {len(names)} sectors {', '.join(names)}")
            rec.hazard = Hazard(rec.t, sectors)
            if "state" in d:
                rec.status = Status(SystemState[d["state"]], 0.0, why=str(d.get("why", "")))
            if "bus_from" in d:
                rec.bus_from = int(d["bus_from"])
        if "camera" in d:
            unseen = set(d.get("unseen") or ())
            rec.visibility = Visibility(Blindness[d["camera"]], tuple(s in unseen for s in names), 0.0)
        if "latency_ms" in d:
            rec.latency_ms = float(d["latency_ms"])
        rec.stage_ms = {str(k): float(v) for k, v in d.get("stage_ms", {}).items()}
        return rec
