"""The bus against the frame log: the level onsets a CAN log carries, decoded with cantools from the
package's DBC and judged as ``bsn-listen`` judges them (:mod:`bsn_edge.alerts.bus_check`), matched with the
frame log's sector by sector, in order. Damaged frames are counted, never onsets.

A frame log's onset that never reached the bus (a level that rose and fell within one send cycle) and a
bus onset no frame explains are both flagged.

Cycle by cycle (:func:`check_cycles`): each trusted hazard frame's levels against those of the frame whose
hazard it carried (the frame log's ``bus_from`` numbers them), every one that differs shown with its time, the
cycles around it and why. A cycle that said UNAVAILABLE carries no levels and is not compared.
"""

from __future__ import annotations

import bisect
from typing import Any

from bsn_edge.alerts.bus_onsets import BusCycle, BusOnset, BusRead, bus_onsets, read_bus
from bsn_edge.alerts.sectors import SECTORS
from bsn_edge.report.drive import Onset
from bsn_edge.runtime.frame_record import FrameRecord

__all__ = ["BusOnset", "BusRead", "bus_onsets", "check", "check_cycles", "read_bus"]


AROUND = 2      # status cycles shown on each side of a disagreement


def check(log_onsets: list[Onset], on_bus: list[BusOnset], statuses: tuple[tuple[float, str], ...] = (),
          start: float | None = None, names: tuple[str, ...] = SECTORS) -> dict[str, Any]:
    """Sector by sector (``names``, the run's), the onsets of the log and of the bus matched in order: the k-th
    rise to a level in one is the k-th rise to it in the other. Returns per sector the counts and what is in one
    only, and every disagreement with its time (the log's clock, or seconds into the CAN log), the bus's states
    around it (``statuses`` and ``start``: :attr:`BusRead.statuses` and :attr:`BusRead.start`) and what explains
    it."""
    out: dict[str, Any] = {"agree": True, "sectors": {}, "disagreements": []}
    t0 = start if start is not None else statuses[0][0] if statuses else on_bus[0].timestamp if on_bus else 0.0
    for name in names:
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


MAX_SHOWN = 50      # cycle disagreements listed one by one; the rest counted


def check_cycles(records: list[FrameRecord], cycles: tuple[BusCycle, ...], start: float = 0.0) -> dict[str, Any]:
    """Each cycle of the bus against the frame whose hazard it carried: the last frame of the log whose
    ``bus_from`` is at most the cycle's number (before any, no levels: every sector NONE). Returns the counts
    (compared, agreeing, not compared: UNAVAILABLE or a lost status with no levels) and the first
    :data:`MAX_SHOWN` disagreements, each with its time (seconds into the CAN log), the frame, both levels, the
    cycles around it and why. ``numbered`` is False for a frame log without ``bus_from`` (nothing compared)."""
    made = [r for r in records if r.hazard is not None and r.bus_from is not None]
    out: dict[str, Any] = {"numbered": bool(made), "compared": 0, "agree": 0, "not_compared": 0,
                           "disagree": 0, "disagreements": []}
    if not made:
        return out
    made.sort(key=lambda r: r.bus_from or 0)
    keys = [r.bus_from or 0 for r in made]
    logged = {r.frame for r in records}
    for i, c in enumerate(cycles):
        none = all(lv == "NONE" for lv in c.levels)
        if c.state == "UNAVAILABLE" or (c.state is None and none):
            out["not_compared"] += 1
            continue
        k = bisect.bisect_right(keys, c.number) - 1
        rec = made[k] if k >= 0 else None
        mine = tuple(s.level.name for s in rec.hazard.sectors) if rec is not None and rec.hazard else \
            ("NONE",) * len(c.levels)
        out["compared"] += 1
        if mine == c.levels:
            out["agree"] += 1
            continue
        out["disagree"] += 1
        if len(out["disagreements"]) < MAX_SHOWN:
            out["disagreements"].append(_cycle_disagreement(c, rec, mine, cycles[max(0, i - AROUND): i + AROUND + 1],
                                                            start, logged))
    return out


def _cycle_disagreement(c: BusCycle, rec: FrameRecord | None, mine: tuple[str, ...], around: tuple[BusCycle, ...],
                        start: float, logged: set[int]) -> dict[str, Any]:
    """One cycle whose levels are not its frame's, with the cycles around it and what explains it (``logged``:
    the frame numbers the log holds)."""
    gap = rec is not None and any(f not in logged for f in range(rec.frame + 1, rec.frame + 3)) \
        and rec.frame != max(logged)
    if rec is None:
        why = "the bus carried levels before the frame log's first hazard"
    elif gap:
        why = "the frame log lacks lines after this frame (dropped or cut): the frame this cycle carried is not in it"
    else:
        why = "the bus carried levels no frame of the log had at this cycle"
    return {"cycle": c.number, "t_s": round(c.timestamp - start, 3), "frame": None if rec is None else rec.frame,
            "bus": list(c.levels), "log": list(mine), "state": c.state,
            "around": [{"cycle": a.number, "t_s": round(a.timestamp - start, 3), "state": a.state,
                        "levels": list(a.levels)} for a in around], "why": why}
