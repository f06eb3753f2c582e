"""The bus against the frame log: the level onsets a CAN log carries, decoded with cantools from the
package's DBC (not the runtime's own decoder), matched with the frame log's sector by sector, in order.

A frame log's onset that never reached the bus (a level that rose and fell within one send cycle) and a
bus onset no frame explains are both flagged.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from bsn_edge.alerts.can_codec import DBC_PATH, HAZARD
from bsn_edge.alerts.sectors import SECTORS
from bsn_edge.alerts.state_machine import Level
from bsn_edge.report.drive import Onset

SIGNALS = {name: f"{name.capitalize()}_Level" for name in SECTORS}     # LEFT -> Left_Level


@dataclass(frozen=True)
class BusOnset:
    """A sector's level rising on the bus: the hazard frame's number among the hazard frames, and its time."""

    sector: str
    level: str
    frame: int
    timestamp: float


def bus_onsets(can_log: str | Path) -> list[BusOnset]:
    """Every level onset the hazard frames of ``can_log`` (``.log`` candump, ``.asc``, ``.blf``) carry.
    ``ValueError`` for a file python-can cannot read."""
    import can
    import cantools

    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, cantools.database.can.Database)    # a DBC file is a CAN database
    hazard = db.get_message_by_name(HAZARD)
    last = dict.fromkeys(SECTORS, 0)
    out: list[BusOnset] = []
    n = 0
    try:
        reader = can.LogReader(str(can_log))
    except Exception as e:
        raise ValueError(f"{can_log}: not a CAN log python-can reads ({type(e).__name__}: {e})") from None
    for msg in reader:
        if msg.arbitration_id != hazard.frame_id:
            continue
        values = cast(dict[str, Any], hazard.decode(bytes(msg.data), decode_choices=False))
        for name, signal in SIGNALS.items():
            level = int(values[signal])
            if level > last[name]:
                out.append(BusOnset(name, Level(level).name, n, float(msg.timestamp)))
            last[name] = level
        n += 1
    return out


def check(log_onsets: list[Onset], on_bus: list[BusOnset]) -> dict[str, Any]:
    """Sector by sector, the onsets of the log and of the bus matched in order: the k-th rise to a level in
    one is the k-th rise to it in the other. Returns per sector the counts and what is in one only."""
    out: dict[str, Any] = {"agree": True, "sectors": {}}
    for name in SECTORS:
        mine = [o.level for o in log_onsets if o.sector == name]
        theirs = [o.level for o in on_bus if o.sector == name]
        only_log, only_bus = _difference(mine, theirs), _difference(theirs, mine)
        out["sectors"][name] = {"log": len(mine), "bus": len(theirs), "only_in_log": only_log,
                                "only_on_bus": only_bus, "log_levels": mine, "bus_levels": theirs}
        out["agree"] &= not only_log and not only_bus
    return out


def _difference(a: list[str], b: list[str]) -> list[str]:
    """The onsets of ``a`` (by level, with multiplicity) that ``b`` does not have."""
    left = list(b)
    missing = []
    for level in a:
        if level in left:
            left.remove(level)
        else:
            missing.append(level)
    return missing
