"""The bus against the frame log: the level onsets a CAN log carries, decoded with cantools from the
package's DBC and judged as ``bsn-listen`` judges them (:mod:`bsn_edge.alerts.bus_check`), matched with the
frame log's sector by sector, in order. Damaged frames are counted, never onsets.

A frame log's onset that never reached the bus (a level that rose and fell within one send cycle) and a
bus onset no frame explains are both flagged.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bsn_edge.alerts.bus_check import FrameChecker, Verdict
from bsn_edge.alerts.can_codec import HAZARD, signal_name
from bsn_edge.alerts.can_log import read_log
from bsn_edge.alerts.health import SystemState
from bsn_edge.alerts.sectors import SECTORS
from bsn_edge.alerts.state_machine import Level
from bsn_edge.report.drive import Onset


@dataclass(frozen=True)
class BusOnset:
    """A sector's level rising on the bus: the hazard frame's number among the hazard frames, and its time."""

    sector: str
    level: str
    frame: int
    timestamp: float


@dataclass(frozen=True)
class BusRead:
    """What a CAN log says: the level onsets of its trusted hazard frames, and what could not be read
    (damaged frames by what was wrong; lines or records that could not be read, counted and the first named)."""

    onsets: list[BusOnset]
    hazard_frames: int
    damaged: dict[str, int]
    unreadable: str = ""
    statuses: tuple[tuple[float, str], ...] = ()      # (time, state) of every trusted status frame, in order
    start: float = 0.0                                # the log's first frame's time


def read_bus(can_log: str | Path) -> BusRead:
    """Every level onset the hazard frames of ``can_log`` (``.log`` candump, ``.asc``, ``.blf``) carry, read as
    ``bsn-listen`` reads them (:func:`~bsn_edge.alerts.can_log.read_log`) and judged as it judges them
    (:class:`FrameChecker`): a damaged frame (bad CRC or counter, an undefined level, a layout that does not
    decode) and a line that cannot be read are counted, never an onset."""
    check = FrameChecker()
    last = dict.fromkeys(SECTORS, 0)
    out: list[BusOnset] = []
    unreadable: list[str] = []
    n = 0

    def bad(where: str, why: str) -> None:
        unreadable.append(f"{where}: {why}")

    pending: tuple[dict[str, Any], int, float] | None = None     # a cycle's hazard, until its status says
    statuses: list[tuple[float, str]] = []
    start: float | None = None

    def apply(signals: dict[str, Any], k: int, t: float) -> None:
        for name in SECTORS:
            level = int(signals[signal_name(name, "Level")])
            if level > last[name]:
                out.append(BusOnset(name, Level(level).name, k, t))
            last[name] = level

    for f in read_log(can_log, bad):
        start = f.timestamp if start is None else start
        c = check(f.frame_id, f.data)
        if c is None:
            continue
        if c.decoded is not None and c.decoded.name != HAZARD:
            # the status after a hazard frame is its cycle's: an UNAVAILABLE cycle (a stall, the last word)
            # carries no hazard, so its levels of NONE are no fall and what follows no new onset
            if c.trusted:
                statuses.append((f.timestamp, SystemState(int(c.decoded.signals["System_State"])).name))
            if pending is not None and c.trusted and int(c.decoded.signals["System_State"]) != SystemState.UNAVAILABLE:
                apply(*pending)
            pending = None
            continue
        n += 1
        if pending is not None:        # a hazard frame with no status of its own (status sent less often)
            apply(*pending)
            pending = None
        if c.decoded is not None and c.trusted:
            pending = (c.decoded.signals, n - 1, f.timestamp)
    if pending is not None:
        apply(*pending)
    damaged = {v.value: k for v, k in check.counts.items() if k and v not in (Verdict.OK, Verdict.REPEATED)}
    said = f"{len(unreadable)} unreadable line(s), the first {unreadable[0]}" if unreadable else ""
    return BusRead(out, n, damaged, said, tuple(statuses), start or 0.0)


def bus_onsets(can_log: str | Path) -> list[BusOnset]:
    """The level onsets of :func:`read_bus`."""
    return read_bus(can_log).onsets


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
