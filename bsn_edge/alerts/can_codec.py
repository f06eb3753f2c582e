"""AlertFrame <-> CAN frames, encoded with cantools from the shipped DBC, with E2E protection."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from bsn_edge.alerts.blindness import Blindness
from bsn_edge.alerts.e2e import AliveCounter, e2e_crc
from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.health import Fault, SystemState
from bsn_edge.alerts.sectors import SECTORS

DBC_PATH = Path(__file__).with_name("bsn_alerts.dbc")
HAZARD, STATUS = "BSN_Hazard", "BSN_Status"
NO_DISTANCE = 63.5
SAT = 255
SIDES = tuple(name.title() for name in SECTORS)   # the DBC's signal prefixes: Left, Centre, Right


def signal_name(sector: str, field: str) -> str:
    """The DBC's signal of ``field`` (Level, Score, Distance) for ``sector`` (LEFT -> Left_Level): the one
    place a sector's signals are named."""
    return f"{sector.title()}_{field}"
SINK_SAT = 63


@lru_cache(maxsize=1)
def database():
    """The shipped DBC, loaded once (cantools is imported here, not at package import)."""
    import cantools

    return cantools.database.load_file(str(DBC_PATH))


def _crc_signal(msg) -> str:
    return next(s.name for s in msg.signals if s.name.endswith("_CRC"))


def _counter_signal(msg) -> str:
    return next(s.name for s in msg.signals if s.name.endswith("_Counter"))


class CanEncoder:
    """Encodes AlertFrames into (arbitration id, data) pairs, one counter per message."""

    def __init__(self) -> None:
        self.db = database()
        self.counters = {HAZARD: AliveCounter(), STATUS: AliveCounter()}

    def _encode(self, name: str, values: dict[str, Any]) -> tuple[int, bytes]:
        msg = self.db.get_message_by_name(name)
        values = {**values, _counter_signal(msg): self.counters[name].next(), _crc_signal(msg): 0}
        data = bytearray(msg.encode(values, strict=True))
        data[7] = e2e_crc(bytes(data[:7]), msg.frame_id)
        return msg.frame_id, bytes(data)

    def encode(self, frame: AlertFrame, messages: tuple[str, ...] | None = None) -> list[tuple[int, bytes]]:
        """The frames of ``messages`` (by name, in the order given; None: every message) for ``frame``;
        only a message sent moves its counter."""
        hz: dict[str, Any] = {}
        for name, s in zip(SIDES, frame.sectors, strict=True):
            hz[f"{name}_Level"] = int(s.level)
            hz[f"{name}_Score"] = round(min(max(s.score, 0.0), 1.0) * 127) / 127
            hz[f"{name}_Distance"] = NO_DISTANCE if s.distance_m is None else min(round(s.distance_m * 2) / 2, 63.0)
            hz[f"{name}_Unseen"] = int(s.unseen)
        f = frame.faults
        st = {"System_State": int(frame.state), "Frame_Rate": min(round(frame.fps * 2) / 2, 127.5),
              "Decode_Errors": min(f.get(Fault.DECODE_ERRORS, 0) + f.get(Fault.SIZE_CHANGES, 0), SAT),
              "Dropped_Frames": min(f.get(Fault.DROPPED_FRAMES, 0), SAT),
              "Invalid_Outputs": min(f.get(Fault.NAN_OUTPUTS, 0), SAT),
              "Tx_Errors": min(sum(f.get(k, 0) for k in (Fault.TX_ERRORS, Fault.TX_FULL, Fault.SERIAL_ERRORS)), SAT),
              "Sink_Errors": min(f.get(Fault.SINK_ERRORS, 0), SINK_SAT),
              "Model_Unsigned": 1 if f.get(Fault.UNSIGNED_MODEL, 0) else 0,
              "Camera_Reason": int(frame.camera)}
        values = {HAZARD: hz, STATUS: st}
        return [self._encode(name, values[name]) for name in (messages if messages is not None else (HAZARD, STATUS))]


@dataclass(frozen=True)
class Decoded:
    """A received frame: message name, decoded signals, and whether its E2E checks passed."""

    name: str
    signals: dict[str, Any]
    crc_ok: bool
    counter: int


def decode(frame_id: int, data: bytes) -> Decoded | None:
    """Decode one CAN frame of the DBC (None for other ids); the CRC is checked, not trusted."""
    db = database()
    try:
        msg = db.get_message_by_frame_id(frame_id)
    except KeyError:
        return None
    sig = msg.decode(bytes(data), decode_choices=False)
    ok = len(data) == 8 and e2e_crc(bytes(data[:7]), frame_id) == data[7]
    return Decoded(msg.name, dict(sig), ok, int(sig[_counter_signal(msg)]))


LEVEL_NAMES = ("NONE", "CAUTION", "WARNING")


def invalid_fields(d: Decoded) -> list[str]:
    """Signals whose raw value the DBC's value table does not define (e.g. a level of 3)."""
    if d.name != HAZARD:
        reason = int(d.signals.get("Camera_Reason", 0))
        return [] if reason in set(Blindness) else [f"Camera_Reason={reason}"]
    return [f"{side}_Level={int(d.signals[f'{side}_Level'])}" for side in SIDES
            if not 0 <= int(d.signals[f"{side}_Level"]) < len(LEVEL_NAMES)]


def to_alert_text(d: Decoded, number: int | None = None) -> str:
    """One line a person can read (a field outside its value table reads ``LEVEL?N``): the message, its
    ``number`` among its message's frames when known (what ``bsn-report`` calls the cycle), its alive
    counter (0-14, wrapping) and its values."""
    s = d.signals
    flag = "" if d.crc_ok else "  CRC MISMATCH"
    which = f"{'hazard' if d.name == HAZARD else 'status'} {'' if number is None else f'{number} '}[alive {d.counter}]"
    if d.name == HAZARD:
        parts = []
        for side in SIDES:
            v = int(s[f"{side}_Level"])
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
