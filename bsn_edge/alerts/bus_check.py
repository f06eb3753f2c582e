"""The one way a received frame is judged: decoded with the layout's DBC, its CRC, its alive counter and its
value tables checked. ``bsn-listen`` prints what it says and ``bsn-report`` takes onsets only from frames it
passes, so the two never read one bus two ways."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from bsn_edge.alerts.can_codec import Decoded, decode, invalid_fields
from bsn_edge.alerts.dbc import BusLayout
from bsn_edge.alerts.e2e import COUNTER_MOD, counter_gap


class Verdict(Enum):
    """What was wrong with a frame, the first thing found (a frame is counted under one verdict only)."""

    OK = "ok"
    UNDECODABLE = "cannot be decoded"       # one of our ids with the wrong length or layout
    BAD_CRC = "bad CRC"                     # nothing in it can be trusted, its counter included
    BAD_COUNTER = "counter outside 0-14"    # 15 is the DBC's 'invalid'
    UNDEFINED = "undefined field"           # a value the DBC's value table does not define (a level of 3)
    REPEATED = "repeated"                   # the same counter twice in a row: a stuck sender


@dataclass(frozen=True)
class Checked:
    """One frame of the DBC as judged: the decoded frame (None when it could not be), the verdict, the
    frames of its message lost before it (by the counter), and the undefined fields or the decode error."""

    decoded: Decoded | None
    verdict: Verdict
    lost: int = 0
    detail: str = ""
    number: int | None = None       # its number among its message's frames sent, from 0 (lost ones counted)

    @property
    def trusted(self) -> bool:
        """Whether its values may be read: decoded, CRC and counter good, every field defined (a repeated
        frame carries good values: it is the sender that is stuck, and that is counted)."""
        return self.verdict in (Verdict.OK, Verdict.REPEATED)


@dataclass
class FrameChecker:
    """Judges a stream of frames in order, decoded with ``layout``'s DBC (the default layout's when None); keeps
    each message's last good counter and the counts."""

    layout: BusLayout | None = None
    last: dict[str, int] = field(default_factory=dict)
    numbers: dict[str, int] = field(default_factory=dict)     # each message's last good frame's number
    counts: dict[Verdict, int] = field(default_factory=lambda: dict.fromkeys(Verdict, 0))
    lost: int = 0

    def __call__(self, frame_id: int, data: bytes) -> Checked | None:
        """The frame judged; None for an id the DBC does not hold (another node's traffic)."""
        try:
            d = decode(frame_id, data, self.layout)
        except Exception as e:  # cantools' errors for a frame of our id that does not fit its layout
            return self._count(Checked(None, Verdict.UNDECODABLE, detail=f"{type(e).__name__}: {e}"))
        if d is None:
            return None
        if not d.crc_ok:
            return self._count(Checked(d, Verdict.BAD_CRC))
        if not 0 <= d.counter < COUNTER_MOD:
            return self._count(Checked(d, Verdict.BAD_COUNTER, detail=f"counter {d.counter}"))
        prev = self.last.get(d.name)
        self.last[d.name] = d.counter
        lost = 0 if prev == d.counter else counter_gap(prev, d.counter)
        self.lost += lost
        # the first frame heard is taken as the sender's frame of its counter (a log from the sender's start)
        number = d.counter if prev is None else self.numbers[d.name] + (prev != d.counter) + lost
        self.numbers[d.name] = number
        bad = invalid_fields(d)
        if bad:
            return self._count(Checked(d, Verdict.UNDEFINED, lost, ", ".join(bad), number))
        return self._count(Checked(d, Verdict.REPEATED if prev == d.counter else Verdict.OK, lost, number=number))

    def _count(self, c: Checked) -> Checked:
        self.counts[c.verdict] += 1
        return c

    @property
    def damaged(self) -> int:
        """Frames whose values could not be trusted (undecodable, bad CRC, bad counter, undefined field)."""
        return sum(n for v, n in self.counts.items() if v not in (Verdict.OK, Verdict.REPEATED))
