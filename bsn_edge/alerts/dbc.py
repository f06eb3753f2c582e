"""The bus's DBC, generated from the sector layout: what ``bsn-run --print-dbc`` writes and the codec encodes with.

A hazard frame carries up to :data:`PER_FRAME` sectors (17 bits each: level 2, unseen 1, score 7, distance 7;
the alive counter and the CRC take the last 12 of its 64 bits). A layout of more sectors gets a second hazard
frame (``BSN_Hazard2``, id 0x502) and a third (``BSN_Hazard3``, 0x503), sent right after the first in every
cycle; ``BSN_Status`` (0x501) is the same for every layout. The default layout's DBC is the one shipped
(``bsn_edge/alerts/bsn_alerts.dbc``; a test holds it to this module).

Within a hazard frame the bits are: the levels (2 each) from bit 0, as many unseen bits as fit the rest of the
first byte, the scores (7 each) from bit 8, the distances (7 each), the other unseen bits; counter at 52, CRC-8
over bytes 0-6 at 56.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

DBC_PATH = Path(__file__).with_name("bsn_alerts.dbc")
HAZARD, STATUS = "BSN_Hazard", "BSN_Status"
HAZARD_ID, STATUS_ID = 0x500, 0x501
PER_FRAME = 3
SCORE_START, COUNTER_START, CRC_START = 8, 52, 56
LEVEL_BITS, SCORE_BITS, DISTANCE_BITS = 2, 7, 7

_HEADER = 'VERSION "bsn-edge 1"\n\n\nNS_ :\n\nBS_:\n\nBU_: BSN DISPLAY\n'
_STATUS = """BO_ 1281 BSN_Status: 8 BSN
 SG_ System_State : 0|2@1+ (1,0) [0|3] "" DISPLAY
 SG_ Sink_Errors : 2|6@1+ (1,0) [0|63] "" DISPLAY
 SG_ Frame_Rate : 8|8@1+ (0.5,0) [0|127.5] "fps" DISPLAY
 SG_ Decode_Errors : 16|8@1+ (1,0) [0|255] "" DISPLAY
 SG_ Dropped_Frames : 24|8@1+ (1,0) [0|255] "" DISPLAY
 SG_ Invalid_Outputs : 32|8@1+ (1,0) [0|255] "" DISPLAY
 SG_ Tx_Errors : 40|8@1+ (1,0) [0|255] "" DISPLAY
 SG_ Model_Unsigned : 48|1@1+ (1,0) [0|1] "" DISPLAY
 SG_ Camera_Reason : 49|3@1+ (1,0) [0|6] "" DISPLAY
 SG_ Status_Counter : 52|4@1+ (1,0) [0|14] "" DISPLAY
 SG_ Status_CRC : 56|8@1+ (1,0) [0|255] "" DISPLAY
"""
# the status's comments, by signal ("" for the message's own), in the file's order
_STATUS_NOTES = (
    ("", "System heartbeat, sent every messages.status_every cycles (every 0.1 s by default, at least once a "
         "second) even when nothing is hazardous. State: 0 OK, 1 DEGRADED, 2 UNAVAILABLE, 3 CALIBRATING. Fault "
         "counters saturate at 255."),
    ("Sink_Errors", "Outputs beside the bus (frame log, CAN log, overlay, maps) that failed during the run; the "
                    "alerts go on and the state is DEGRADED. Saturates at 63."),
    ("Model_Unsigned", "1: the model running is not signed by a trusted key; it runs only because the runtime was "
                       "told to (--allow-unsigned). Its answers are not vouched for by anyone the system trusts."),
    ("Camera_Reason", "Why the camera cannot see: 0 clear; 1-5 the picture as a whole (System_State UNAVAILABLE); 6 "
                      "some sectors (their Unseen bits, System_State DEGRADED). Raised after visibility.onset_s, "
                      "cleared after visibility.clear_s of a clear picture."),
    ("Frame_Rate", "Valid inferences per second the runtime achieved over the last health.window_s (2 s by "
                   "default): its processing rate, not the rate of the video or camera it reads."),
)
_STATUS_VALUES = """VAL_ 1281 System_State 0 "OK" 1 "DEGRADED" 2 "UNAVAILABLE" 3 "CALIBRATING" ;
VAL_ 1281 Model_Unsigned 0 "SIGNED" 1 "UNSIGNED" ;
VAL_ 1281 Camera_Reason 0 "CLEAR" 1 "COVERED" 2 "SATURATED" 3 "FROZEN" 4 "NOISE" 5 "BLUR" 6 "PARTIAL" ;
"""
_UNSEEN_NOTE = ("1: the camera cannot see this sector (covered, blinded, or the whole picture lost: Camera_Reason says "
                "why); its level says nothing of what is there.")


def signal_name(sector: str, field: str) -> str:
    """The DBC's signal of ``field`` (Level, Score, Distance, Unseen) for ``sector`` (LEFT -> Left_Level,
    FAR_LEFT -> Far_Left_Level): the one place a sector's signals are named."""
    return f"{sector.title()}_{field}"


@dataclass(frozen=True)
class HazardFrame:
    """One hazard message of a layout: its name, CAN id, the prefix of its counter and CRC signals, and the
    sectors it carries (left to right)."""

    name: str
    frame_id: int
    prefix: str
    sectors: tuple[str, ...]

    def signals(self) -> list[tuple[str, int, int, str, str, str]]:
        """(name, start bit, length, factor, range, unit) of each signal, in bit order."""
        n = len(self.sectors)
        lead = min(n, 8 - LEVEL_BITS * n)          # unseen bits that fit the first byte beside the levels
        out = [(signal_name(s, "Level"), LEVEL_BITS * k, LEVEL_BITS, "1", "0|2", "")
               for k, s in enumerate(self.sectors)]
        out += [(signal_name(s, "Unseen"), LEVEL_BITS * n + k, 1, "1", "0|1", "")
                for k, s in enumerate(self.sectors[:lead])]
        out += [(signal_name(s, "Score"), SCORE_START + SCORE_BITS * k, SCORE_BITS, "0.0078740157480315", "0|1", "")
                for k, s in enumerate(self.sectors)]
        start = SCORE_START + SCORE_BITS * n
        out += [(signal_name(s, "Distance"), start + DISTANCE_BITS * k, DISTANCE_BITS, "0.5", "0|63.5", "m")
                for k, s in enumerate(self.sectors)]
        start += DISTANCE_BITS * n
        out += [(signal_name(s, "Unseen"), start + k, 1, "1", "0|1", "") for k, s in enumerate(self.sectors[lead:])]
        return [*out, (f"{self.prefix}_Counter", COUNTER_START, 4, "1", "0|14", ""),
                (f"{self.prefix}_CRC", CRC_START, 8, "1", "0|255", "")]


@dataclass(frozen=True)
class BusLayout:
    """What the bus carries for a sector layout (``sectors``: the names, left to right): its hazard frames, the
    DBC text and the database cantools makes of it."""

    sectors: tuple[str, ...]

    @property
    def hazards(self) -> tuple[HazardFrame, ...]:
        """The hazard frames, in the order they go out within a cycle."""
        chunks = [self.sectors[k:k + PER_FRAME] for k in range(0, len(self.sectors), PER_FRAME)]
        return tuple(HazardFrame(HAZARD if k == 0 else f"{HAZARD}{k + 1}", HAZARD_ID if k == 0 else STATUS_ID + k,
                                 "Hazard" if k == 0 else f"Hazard{k + 1}", chunk) for k, chunk in enumerate(chunks))

    @property
    def hazard_names(self) -> tuple[str, ...]:
        return tuple(h.name for h in self.hazards)

    def text(self) -> str:
        """The DBC file."""
        blocks = [_HEADER, ""]
        for h in self.hazards:
            blocks.append(f"BO_ {h.frame_id} {h.name}: 8 BSN\n" + "".join(
                f' SG_ {name} : {start}|{length}@1+ ({factor},0) [{span}] "{unit}" DISPLAY\n'
                for name, start, length, factor, span, unit in h.signals()))
        blocks += [_STATUS, ""]
        notes = []
        for k, h in enumerate(self.hazards):
            which = ("" if len(self.hazards) == 1 else
                     f" This frame carries {', '.join(h.sectors)}; the layout's hazard frames go out together, "
                     f"{', '.join(self.hazard_names)}, in that order.")
            first = "" if k else " Levels: 0 none, 1 caution, 2 warning. Distance 63.5 m = no blind spot in range."
            listed = ", ".join(self.sectors)
            notes.append(f'CM_ BO_ {h.frame_id} "Blind-spot hazard per sector, left to right {listed}, sent every '
                         "messages.hazard_every cycles of runtime.cycle_s (every 0.1 s by default)."
                         f"{first}{which} Counter 0..14, CRC-8 SAE J1850 over bytes 0..6 and the data ID.\";\n")
        notes += [f'CM_ SG_ {h.frame_id} {signal_name(s, "Unseen")} "{_UNSEEN_NOTE}";\n'
                  for h in self.hazards for s in h.sectors]
        values = [f'VAL_ {h.frame_id} {signal_name(s, "Level")} 0 "NONE" 1 "CAUTION" 2 "WARNING" ;\n'
                  f'VAL_ {h.frame_id} {signal_name(s, "Unseen")} 0 "SEEN" 1 "UNSEEN" ;\n'
                  for h in self.hazards for s in h.sectors]
        status = "".join(f'CM_ BO_ {STATUS_ID} "{text}";\n' if not signal else
                         f'CM_ SG_ {STATUS_ID} {signal} "{text}";\n' for signal, text in _STATUS_NOTES)
        return "\n".join(blocks) + "\n" + "".join(notes) + status + "".join(values) + _STATUS_VALUES

    def database(self) -> Any:
        """The cantools database of :meth:`text` (made once per layout)."""
        return _database(self.sectors)

    def sector_of(self, message: str) -> tuple[str, ...]:
        """The sectors hazard message ``message`` carries (() for the status)."""
        return next((h.sectors for h in self.hazards if h.name == message), ())


@lru_cache(maxsize=8)
def _database(sectors: tuple[str, ...]) -> Any:
    import cantools  # imported here, not at package import

    return cantools.database.load_string(BusLayout(sectors).text(), database_format="dbc")


def bus_layout(sectors: tuple[str, ...] | None = None) -> BusLayout:
    """The bus of layout ``sectors`` (None: the default layout's, LEFT, CENTRE, RIGHT)."""
    from bsn_edge.alerts.sectors import SECTORS

    return BusLayout(tuple(sectors) if sectors is not None else SECTORS)
