"""AlertFrame <-> CAN frames, encoded with cantools from the layout's DBC (:mod:`bsn_edge.alerts.dbc`), with E2E
protection."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bsn_edge.alerts.blindness import WHOLE, Blindness
from bsn_edge.alerts.dbc import DBC_PATH, HAZARD, STATUS, BusLayout, bus_layout, signal_name
from bsn_edge.alerts.e2e import AliveCounter, e2e_crc
from bsn_edge.alerts.frame import AlertFrame, SectorAlert
from bsn_edge.alerts.health import Fault, SystemState
from bsn_edge.alerts.state_machine import Level

__all__ = ["DBC_PATH", "HAZARD", "STATUS", "CanEncoder", "Decoded", "decode", "invalid_fields", "signal_name",
           "to_alert_text"]
NO_DISTANCE = 63.5
SAT = 255
SINK_SAT = 63


def _crc_signal(msg) -> str:
    return next(s.name for s in msg.signals if s.name.endswith("_CRC"))


def _counter_signal(msg) -> str:
    return next(s.name for s in msg.signals if s.name.endswith("_Counter"))


def _signals(name: str, s: SectorAlert) -> tuple[tuple[str, Any], ...]:
    """A sector's reading as its hazard signals' values, as the DBC scales and saturates them."""
    distance = NO_DISTANCE if s.distance_m is None else min(round(s.distance_m * 2) / 2, 63.0)
    return ((signal_name(name, "Level"), int(s.level)),
            (signal_name(name, "Score"), round(min(max(s.score, 0.0), 1.0) * 127) / 127),
            (signal_name(name, "Distance"), distance), (signal_name(name, "Unseen"), int(s.unseen)))


class CanEncoder:
    """Encodes AlertFrames into (arbitration id, data) pairs, one counter per message, with the DBC of ``layout``
    (the default layout's when None)."""

    def __init__(self, layout: BusLayout | None = None) -> None:
        self.layout = layout or bus_layout()
        self.db = self.layout.database()
        names = (*self.layout.hazard_names, STATUS)
        self.counters = {name: AliveCounter() for name in names}
        # each message, its counter's and its CRC's signal, looked up once rather than every cycle
        self.messages = {name: (m, _counter_signal(m), _crc_signal(m))
                         for name in names for m in (self.db.get_message_by_name(name),)}

    def _encode(self, name: str, values: dict[str, Any]) -> tuple[int, bytes]:
        msg, counter, crc = self.messages[name]
        values = {**values, counter: self.counters[name].next(), crc: 0}
        data = bytearray(msg.encode(values, strict=True))
        data[7] = e2e_crc(bytes(data[:7]), msg.frame_id)
        return msg.frame_id, bytes(data)

    def encode(self, frame: AlertFrame, messages: tuple[str, ...] | None = None) -> list[tuple[int, bytes]]:
        """The frames of ``messages`` (by name, in the order given; None: every message; ``BSN_Hazard`` stands for
        every hazard frame of the layout) for ``frame``; only a message sent moves its counter."""
        sectors = frame.sectors
        if not sectors:         # no hazard yet (the bus's first cycles), or the last word: nothing to warn of
            sectors = (SectorAlert(0.0, Level.NONE, None, frame.camera in WHOLE),) * len(self.layout.sectors)
        if len(sectors) != len(self.layout.sectors):
            raise ValueError(f"a frame of {len(frame.sectors)} sectors for a bus of {len(self.layout.sectors)} "
                             f"({', '.join(self.layout.sectors)})")
        reading = dict(zip(self.layout.sectors, sectors, strict=True))
        f = frame.faults
        st = {"System_State": int(frame.state), "Frame_Rate": min(round(frame.fps * 2) / 2, 127.5),
              "Decode_Errors": min(f.get(Fault.DECODE_ERRORS, 0) + f.get(Fault.SIZE_CHANGES, 0), SAT),
              "Dropped_Frames": min(f.get(Fault.DROPPED_FRAMES, 0), SAT),
              "Invalid_Outputs": min(f.get(Fault.NAN_OUTPUTS, 0), SAT),
              "Tx_Errors": min(sum(f.get(k, 0) for k in (Fault.TX_ERRORS, Fault.TX_FULL, Fault.SERIAL_ERRORS)), SAT),
              "Sink_Errors": min(f.get(Fault.SINK_ERRORS, 0), SINK_SAT),
              "Model_Unsigned": 1 if f.get(Fault.UNSIGNED_MODEL, 0) else 0,
              "Camera_Reason": int(frame.camera)}
        out = []
        for name in messages if messages is not None else (HAZARD, STATUS):
            if name == STATUS:
                out.append(self._encode(STATUS, st))
                continue
            for h in self.layout.hazards:      # each hazard frame carries its own sectors
                out.append(self._encode(h.name, {k: v for name in h.sectors for k, v in _signals(name, reading[name])}))
        return out


@dataclass(frozen=True)
class Decoded:
    """A received frame: message name, decoded signals, and whether its E2E checks passed."""

    name: str
    signals: dict[str, Any]
    crc_ok: bool
    counter: int


def decode(frame_id: int, data: bytes, layout: BusLayout | None = None) -> Decoded | None:
    """Decode one CAN frame of ``layout``'s DBC (the default layout's when None; None for other ids); the CRC is
    checked, not trusted."""
    db = (layout or bus_layout()).database()
    try:
        msg = db.get_message_by_frame_id(frame_id)
    except KeyError:
        return None
    sig = msg.decode(bytes(data), decode_choices=False)
    ok = len(data) == 8 and e2e_crc(bytes(data[:7]), frame_id) == data[7]
    return Decoded(msg.name, dict(sig), ok, int(sig[_counter_signal(msg)]))


LEVEL_NAMES = ("NONE", "CAUTION", "WARNING")


def _levels(d: Decoded) -> list[str]:
    """The level signals of a hazard frame, left to right."""
    return [k for k in d.signals if k.endswith("_Level")]


def invalid_fields(d: Decoded) -> list[str]:
    """Signals whose raw value the DBC's value table does not define (e.g. a level of 3)."""
    if d.name == STATUS:
        reason = int(d.signals.get("Camera_Reason", 0))
        return [] if reason in set(Blindness) else [f"Camera_Reason={reason}"]
    return [f"{k}={int(d.signals[k])}" for k in _levels(d) if not 0 <= int(d.signals[k]) < len(LEVEL_NAMES)]


def to_alert_text(d: Decoded, number: int | None = None) -> str:
    """One line a person can read (a field outside its value table reads ``LEVEL?N``): the message, its
    ``number`` among its message's frames when known (what ``bsn-report`` calls the cycle), its alive
    counter (0-14, wrapping) and its values."""
    s = d.signals
    flag = "" if d.crc_ok else "  CRC MISMATCH"
    kind = "status" if d.name == STATUS else d.name.removeprefix("BSN_").lower()     # hazard, hazard2
    which = f"{kind} {'' if number is None else f'{number} '}[alive {d.counter}]"
    if d.name != STATUS:
        parts = []
        for level in _levels(d):
            side = level.removesuffix("_Level")
            v = int(s[level])
            lv = LEVEL_NAMES[v] if 0 <= v < len(LEVEL_NAMES) else f"LEVEL?{v}"
            dist = s[f"{side}_Distance"]
            where = "" if dist >= NO_DISTANCE else f" {dist:.1f} m"
            unseen = " UNSEEN" if int(s.get(f"{side}_Unseen", 0)) else ""
            parts.append(f"{side.upper()} {lv} {s[f'{side}_Score']:.2f}{where}{unseen}")
        return f"{which}: " + " | ".join(parts) + flag
    state = SystemState(int(s["System_State"])).name
    return (f"{which}: {state} {s['Frame_Rate']:.1f} fps, decode errors {int(s['Decode_Errors'])}, "
            f"dropped {int(s['Dropped_Frames'])}, invalid outputs {int(s['Invalid_Outputs'])}, "
            f"tx errors {int(s['Tx_Errors'])}, sink errors {int(s.get('Sink_Errors', 0))}"
            + (", model UNSIGNED" if int(s.get("Model_Unsigned", 0)) else "") + _camera_text(s) + flag)


def _camera_text(signals: dict[str, Any]) -> str:
    """``, camera COVERED`` for a status whose camera cannot see (the raw number when undefined)."""
    reason = int(signals.get("Camera_Reason", 0))
    if reason == Blindness.CLEAR:
        return ""
    return f", camera {Blindness(reason).name}" if reason in set(Blindness) else f", camera REASON?{reason}"
