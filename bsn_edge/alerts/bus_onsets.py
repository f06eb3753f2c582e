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


@dataclass
class _Pending:
    """A cycle's hazard as read so far (the signals of its trusted hazard frames), until its status says."""

    signals: dict[str, Any]
    k: int              # its first hazard frame's place among the log's hazard frames
    t: float
    number: int         # that frame's number among those the sender sent


class _BusReader:
    """The log's frames in order, judged (:class:`FrameChecker`), gathered into cycles and onsets."""

    def __init__(self, sectors: tuple[str, ...] | None) -> None:
        layout = bus_layout(sectors)
        self.names = layout.sectors
        self.check = FrameChecker(layout=layout)
        self.last = dict.fromkeys(self.names, 0)
        self.onsets: list[BusOnset] = []
        self.cycles: list[BusCycle] = []
        self.statuses: list[tuple[float, str]] = []
        self.unreadable: list[str] = []
        self.pending: _Pending | None = None
        self.hazards = 0

    def bad(self, where: str, why: str) -> None:
        self.unreadable.append(f"{where}: {why}")

    def frame(self, frame_id: int, data: bytes, t: float) -> None:
        c = self.check(frame_id, data)
        if c is None:
            return
        if c.decoded is not None and c.decoded.name == STATUS:
            # the status after a hazard frame is its cycle's: an UNAVAILABLE cycle (a stall, the last word)
            # carries no hazard, so its levels of NONE are no fall and what follows no new onset
            state = SystemState(int(c.decoded.signals["System_State"])).name if c.trusted else None
            if state is not None:
                self.statuses.append((t, state))
            self.close(state, apply=state is not None and state != SystemState.UNAVAILABLE.name)
            return
        if c.decoded is not None and c.decoded.name != HAZARD:     # a later hazard frame of the cycle
            if self.pending is not None and c.trusted:
                self.pending.signals.update(c.decoded.signals)
            return
        self.hazards += 1
        self.close(None, apply=True)      # a hazard frame with no status of its own (status sent less often)
        if c.decoded is not None and c.trusted:
            self.pending = _Pending(dict(c.decoded.signals), self.hazards - 1, t, c.number or 0)

    def close(self, state: str | None, apply: bool) -> None:
        """The pending cycle ended by a status of ``state`` (None: none, or untrusted); its onsets taken when
        ``apply``. A cycle missing a sector's level (a later hazard frame lost) has none."""
        p, self.pending = self.pending, None
        if p is None or not all(signal_name(name, "Level") in p.signals for name in self.names):
            return
        levels = [int(p.signals[signal_name(name, "Level")]) for name in self.names]
        self.cycles.append(BusCycle(p.number, p.t, tuple(Level(v).name for v in levels), state))
        if not apply:
            return
        for name, level in zip(self.names, levels, strict=True):
            if level > self.last[name]:
                self.onsets.append(BusOnset(name, Level(level).name, p.k, p.t))
            self.last[name] = level


def read_bus(can_log: str | Path, sectors: tuple[str, ...] | None = None) -> BusRead:
    """Every level onset the hazard frames of ``can_log`` (``.log`` candump, ``.asc``, ``.blf``) carry for the
    layout of ``sectors`` (the default layout's when None), read as ``bsn-listen`` reads them
    (:func:`~bsn_edge.alerts.can_log.read_log`) and judged as it judges them (:class:`FrameChecker`): a damaged
    frame (bad CRC or counter, an undefined level, a layout that does not decode) and a line that cannot be read
    are counted, never an onset. A layout of more than one hazard frame is read a cycle at a time: the first
    hazard frame opens it, the others add their sectors; a cycle missing a sector's trusted frame has no levels."""
    r = _BusReader(sectors)
    start: float | None = None
    for f in read_log(can_log, r.bad):
        start = f.timestamp if start is None else start
        r.frame(f.frame_id, f.data, f.timestamp)
    r.close(None, apply=True)
    damaged = {v.value: k for v, k in r.check.counts.items() if k and v not in (Verdict.OK, Verdict.REPEATED)}
    said = f"{len(r.unreadable)} unreadable line(s), the first {r.unreadable[0]}" if r.unreadable else ""
    return BusRead(r.onsets, r.hazards, damaged, said, tuple(r.statuses), start or 0.0, tuple(r.cycles))


def bus_onsets(can_log: str | Path, sectors: tuple[str, ...] | None = None) -> list[BusOnset]:
    """The level onsets of :func:`read_bus`."""
    return read_bus(can_log, sectors).onsets
