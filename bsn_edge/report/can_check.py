"""The bus against the frame log: the level onsets a CAN log carries, decoded with cantools from the
package's DBC and judged as ``bsn-listen`` judges them (:mod:`bsn_edge.alerts.bus_check`), matched with the
frame log's sector by sector, in order. Damaged frames are counted, never onsets.

A frame log's onset that never reached the bus (a level that rose and fell within one send cycle) and a
bus onset no frame explains are both flagged.
"""

from __future__ import annotations

from typing import Any

from bsn_edge.alerts.bus_onsets import BusOnset, BusRead, bus_onsets, read_bus
from bsn_edge.alerts.sectors import SECTORS
from bsn_edge.report.drive import Onset

__all__ = ["BusOnset", "BusRead", "bus_onsets", "check", "read_bus"]


AROUND = 2      # status cycles shown on each side of a disagreement


def check(log_onsets: list[Onset], on_bus: list[BusOnset], statuses: tuple[tuple[float, str], ...] = (),
          start: float | None = None) -> dict[str, Any]:
    """Sector by sector, the onsets of the log and of the bus matched in order: the k-th rise to a level in
    one is the k-th rise to it in the other. Returns per sector the counts and what is in one only, and every
    disagreement with its time (the log's clock, or seconds into the CAN log), the bus's states around it
    (``statuses`` and ``start``: :attr:`BusRead.statuses` and :attr:`BusRead.start`) and what explains it."""
    out: dict[str, Any] = {"agree": True, "sectors": {}, "disagreements": []}
    t0 = start if start is not None else statuses[0][0] if statuses else on_bus[0].timestamp if on_bus else 0.0
    for name in SECTORS:
        mine = [o for o in log_onsets if o.sector == name]
        theirs = [o for o in on_bus if o.sector == name]
        only_log = _unmatched(mine, theirs)
        only_bus = _unmatched(theirs, mine)
        out["sectors"][name] = {"log": len(mine), "bus": len(theirs), "only_in_log": [o.level for o in only_log],
                                "only_on_bus": [o.level for o in only_bus], "log_levels": [o.level for o in mine],
                                "bus_levels": [o.level for o in theirs]}
        out["agree"] &= not only_log and not only_bus
        out["disagreements"] += [
            {"sector": name, "level": o.level, "where": "frame log only", "t_s": round(o.t, 3), "frame": o.frame,
             "around": [], "why": "a rise the bus never carried: the level fell again before the next send cycle, "
                                  "or that cycle was lost"} for o in only_log]
        out["disagreements"] += [_on_bus_only(o, statuses, t0) for o in only_bus]
    out["disagreements"].sort(key=lambda d: (d["where"], d["t_s"]))
    return out


def _on_bus_only(o: BusOnset, statuses: tuple[tuple[float, str], ...], t0: float) -> dict[str, Any]:
    """A bus onset no onset of the frame log explains, with the bus's states of the cycles around it."""
    k = next((i for i, (t, _) in enumerate(statuses) if t >= o.timestamp), len(statuses))
    around = [{"t_s": round(t - t0, 3), "state": st} for t, st in statuses[max(0, k - AROUND): k + AROUND + 1]]
    before = [st for _, st in statuses[max(0, k - AROUND): k]]
    why = ("no rise of the frame log to this level explains it; the bus said UNAVAILABLE just before (a stall or the "
           "camera: no levels then), so the level on either side of it was one rise in the frame log"
           if "UNAVAILABLE" in before else "no rise of the frame log to this level explains it")
    return {"sector": o.sector, "level": o.level, "where": "bus only", "t_s": round(o.timestamp - t0, 3),
            "frame": o.frame, "around": around, "why": why}


def _unmatched(a: list[Any], b: list[Any]) -> list[Any]:
    """The onsets of ``a`` that ``b`` has no partner for: the k-th rise to a level pairs with the k-th rise to
    it in ``b``; the rest, in order."""
    partners = {level: sum(1 for o in b if o.level == level) for level in {o.level for o in a}}
    out = []
    for o in a:
        if partners[o.level] > 0:
            partners[o.level] -= 1
        else:
            out.append(o)
    return out
