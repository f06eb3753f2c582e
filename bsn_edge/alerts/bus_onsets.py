"""The level onsets a CAN log carries, read as ``bsn-listen`` reads every frame (:mod:`~bsn_edge.alerts.can_log`)
and judged as it judges them (:mod:`~bsn_edge.alerts.bus_check`): damaged frames are counted, never onsets, and a
cycle that said UNAVAILABLE (a stall, the last word) carries no levels, so the level after it is no new rise.
``bsn-report`` matches them with the frame log's; ``bsn-listen --onsets`` prints them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bsn_edge.alerts.bus_check import FrameChecker, Verdict
from bsn_edge.alerts.can_codec import STATUS, signal_name
from bsn_edge.alerts.can_log import read_log
from bsn_edge.alerts.dbc import HAZARD, bus_layout
from bsn_edge.alerts.health import SystemState
from bsn_edge.alerts.state_machine import Level


@dataclass(frozen=True)
class BusOnset:
    """A sector's level rising on the bus: the hazard frame's number among the hazard frames, and its time."""

    sector: str
    level: str
    frame: int
    timestamp: float


@dataclass(frozen=True)
class BusCycle:
    """A send cycle as the bus carried it: its hazard frame's number among those the sender sent (from 0, by the
    alive counter, the frames lost before it included), its time, each sector's level, and the state of the
    status frame that closed the cycle (None when the cycle had none: the status goes out less often)."""

    number: int
    timestamp: float
    levels: tuple[str, ...]
    state: str | None


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
    cycles: tuple[BusCycle, ...] = ()                 # every trusted hazard frame with its cycle's state


def read_bus(can_log: str | Path, sectors: tuple[str, ...] | None = None) -> BusRead:
    """Every level onset the hazard frames of ``can_log`` (``.log`` candump, ``.asc``, ``.blf``) carry for the
    layout of ``sectors`` (the default layout's when None), read as ``bsn-listen`` reads them
    (:func:`~bsn_edge.alerts.can_log.read_log`) and judged as it judges them (:class:`FrameChecker`): a damaged
    frame (bad CRC or counter, an undefined level, a layout that does not decode) and a line that cannot be read
    are counted, never an onset. A layout of more than one hazard frame is read a cycle at a time: the first
    hazard frame opens it, the others add their sectors; a cycle missing a sector's trusted frame has no levels."""
    layout = bus_layout(sectors)
    names = layout.sectors
    check = FrameChecker(layout=layout)
    last = dict.fromkeys(names, 0)
    out: list[BusOnset] = []
    unreadable: list[str] = []
    n = 0

    def bad(where: str, why: str) -> None:
        unreadable.append(f"{where}: {why}")

    pending: tuple[dict[str, Any], int, float, int] | None = None     # a cycle's hazard, until its status says
    statuses: list[tuple[float, str]] = []
    cycles: list[BusCycle] = []
    start: float | None = None

    def whole(signals: dict[str, Any]) -> bool:
        return all(signal_name(name, "Level") in signals for name in names)

    def close(signals: dict[str, Any], number: int, t: float, state: str | None) -> None:
        if whole(signals):
            levels = tuple(Level(int(signals[signal_name(name, "Level")])).name for name in names)
            cycles.append(BusCycle(number, t, levels, state))

    def apply(signals: dict[str, Any], k: int, t: float) -> None:
        if not whole(signals):
            return
        for name in names:
            level = int(signals[signal_name(name, "Level")])
            if level > last[name]:
                out.append(BusOnset(name, Level(level).name, k, t))
            last[name] = level

    for f in read_log(can_log, bad):
        start = f.timestamp if start is None else start
        c = check(f.frame_id, f.data)
        if c is None:
            continue
        if c.decoded is not None and c.decoded.name == STATUS:
            # the status after a hazard frame is its cycle's: an UNAVAILABLE cycle (a stall, the last word)
            # carries no hazard, so its levels of NONE are no fall and what follows no new onset
            state = SystemState(int(c.decoded.signals["System_State"])).name if c.trusted else None
            if state is not None:
                statuses.append((f.timestamp, state))
            if pending is not None:
                close(pending[0], pending[3], pending[2], state)
                if state is not None and state != SystemState.UNAVAILABLE.name:
                    apply(*pending[:3])
            pending = None
            continue
        if c.decoded is not None and c.decoded.name != HAZARD:     # a later hazard frame of the cycle
            if pending is not None and c.trusted:
                pending[0].update(c.decoded.signals)
            continue
        n += 1
        if pending is not None:        # a hazard frame with no status of its own (status sent less often)
            close(pending[0], pending[3], pending[2], None)
            apply(*pending[:3])
            pending = None
        if c.decoded is not None and c.trusted:
            pending = (dict(c.decoded.signals), n - 1, f.timestamp, c.number or 0)
    if pending is not None:
        close(pending[0], pending[3], pending[2], None)
        apply(*pending[:3])
    damaged = {v.value: k for v, k in check.counts.items() if k and v not in (Verdict.OK, Verdict.REPEATED)}
    said = f"{len(unreadable)} unreadable line(s), the first {unreadable[0]}" if unreadable else ""
    return BusRead(out, n, damaged, said, tuple(statuses), start or 0.0, tuple(cycles))


def bus_onsets(can_log: str | Path, sectors: tuple[str, ...] | None = None) -> list[BusOnset]:
    """The level onsets of :func:`read_bus`."""
    return read_bus(can_log, sectors).onsets
