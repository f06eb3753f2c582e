"""One line of the frame log (``bsn-run --log``): :class:`FrameRecord`.

Fields, in the order written (a field that does not apply to the frame is left out):
``frame`` (index in the source), ``t`` (seconds on the source's clock), ``fault`` (what went wrong
with this frame, by the names of :class:`~bsn_edge.alerts.health.Fault`: ``decode_errors``,
``size_changes``, ``nan_outputs``), ``levels`` (LEFT, CENTRE, RIGHT: ``NONE``, ``CAUTION`` or
``WARNING``), ``scores`` (smoothed, 0-1), ``distances`` (metres to the nearest blind spot, null for
none), ``state`` (the system state sent with it) and ``latency_ms``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.health import Fault


@dataclass
class FrameRecord:
    """What the loop knows of one frame, filled in stage by stage."""

    frame: int
    t: float
    fault: Fault | None = None
    alert: AlertFrame | None = None
    latency_ms: float | None = None

    def to_json(self) -> dict[str, Any]:
        """The frame log's line (rounded as written)."""
        out: dict[str, Any] = {"frame": self.frame, "t": round(self.t, 4)}
        if self.fault is not None:
            out["fault"] = self.fault.value
        if self.alert is not None:
            sectors = self.alert.sectors
            out.update(levels=[s.level.name for s in sectors], scores=[round(s.score, 3) for s in sectors],
                       distances=[None if s.distance_m is None else round(s.distance_m, 2) for s in sectors],
                       state=self.alert.state.name)
        if self.latency_ms is not None:
            out["latency_ms"] = round(self.latency_ms, 2)
        return out
