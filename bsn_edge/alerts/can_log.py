"""Reading a CAN log back, one way for every reader (``bsn-listen``, ``bsn-report``): candump ``.log`` line by
line (a damaged line is named and skipped, the rest read on) and python-can's other formats record by record
(a damaged record ends what can be read, said once). Each frame comes with its time and where it was."""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

# candump -L: "(1700000000.123456) can0 500#0011223344556677", python-can adds " T" / " R" (direction)
CANDUMP = re.compile(r"^\((\d+(?:\.\d+)?)\)\s+\S+\s+([0-9A-Fa-f]{1,8})#([0-9A-Fa-f]*)(?:\s+[TR])?\s*$")
PYTHON_CAN_LOGS = (".asc", ".blf", ".csv", ".db", ".mf4", ".trc")
ECHO_CHARS = 60     # of a bad line or message echoed back: enough to recognise it, never a whole megabyte
MAX_LINE = 4096     # a candump line is under 60 characters: a longer one (NUL padding, a binary file) is damage

BadLine = Callable[[str, str], None]     # (where, why)


@dataclass(frozen=True)
class LoggedFrame:
    """One frame of a log: its id, its bytes, its time (seconds, the log's clock) and where it was."""

    frame_id: int
    data: bytes
    timestamp: float
    where: str


def short(text: str) -> str:
    """``text`` cut to :data:`ECHO_CHARS` for a message (its length said)."""
    return text if len(text) <= ECHO_CHARS else f"{text[:ECHO_CHARS]}... ({len(text)} characters)"


def is_log(path: Path) -> bool:
    """Whether ``path``'s extension is a CAN log this module reads."""
    return path.suffix.lower() == ".log" or path.suffix.lower() in PYTHON_CAN_LOGS


def read_log(path: str | Path, bad: BadLine) -> Iterator[LoggedFrame]:
    """The frames of the log at ``path`` in order; every line or record that cannot be read goes to ``bad``."""
    path = Path(path)
    return _candump(path, bad) if path.suffix.lower() == ".log" else _python_can(path, bad)


def _candump(path: Path, bad: BadLine) -> Iterator[LoggedFrame]:
    with open(path, "rb") as f:
        n = 0
        while raw := f.readline(MAX_LINE + 1):
            n += 1
            where = f"{path}:{n}"
            if len(raw) > MAX_LINE:
                # read on to the line's end a block at a time: never the whole of a line with no end
                size = len(raw)
                while not raw.endswith(b"\n") and (raw := f.readline(1 << 16)):
                    size += len(raw)
                bad(where, f"a line of {size} bytes or more: not a candump line")
                continue
            text = raw.decode("utf-8", errors="replace").strip()
            if not text or text.startswith(("#", ";")):
                if text:
                    bad(where, "comment line skipped")
                continue
            m = CANDUMP.match(text)
            if m is None:
                bad(where, f"not a candump line: {short(text)!r}")
                continue
            payload = m.group(3)
            if len(payload) % 2 or len(payload) > 16:
                bad(where, f"truncated or oversized data {short(payload)!r}")
                continue
            yield LoggedFrame(int(m.group(2), 16), bytes.fromhex(payload), float(m.group(1)), where)


def _python_can(path: Path, bad: BadLine) -> Iterator[LoggedFrame]:
    import can

    try:
        reader = iter(can.LogReader(str(path)))
    except Exception as e:  # not a log of that kind at all: an unreadable file, as a damaged record is
        bad(str(path), f"unreadable ({type(e).__name__}: {short(str(e))})")
        return
    while True:
        try:
            msg = next(reader)
        except StopIteration:
            return
        except Exception as e:  # a damaged record: python-can cannot go on after it
            bad(str(path), f"unreadable from here on ({type(e).__name__}: {short(str(e))})")
            return
        yield LoggedFrame(msg.arbitration_id, bytes(msg.data), float(msg.timestamp), str(path))
