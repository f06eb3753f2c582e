"""``bsn-listen``: decode and print what bsn-run sends, checking counters and CRCs."""

from __future__ import annotations

import argparse
import re
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from bsn_edge.alerts.can_codec import decode, invalid_fields, to_alert_text
from bsn_edge.alerts.e2e import COUNTER_MOD, counter_gap
from bsn_edge.alerts.serial_codec import FrameDecoder
from bsn_edge.cli.common import fail

PROG = "bsn-listen"
# candump -L: "(1700000000.123456) can0 500#0011223344556677", python-can adds " T" / " R" (direction)
CANDUMP = re.compile(r"^\((\d+(?:\.\d+)?)\)\s+\S+\s+([0-9A-Fa-f]{1,8})#([0-9A-Fa-f]*)(?:\s+[TR])?\s*$")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description="Decode bsn-run's alerts from a CAN bus, a CAN log or a "
                                "serial port, with the decoders the tests use; report CRC mismatches, repeated and "
                                "lost frames, and log lines that cannot be read. Exit code 1 when anything was wrong.")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--can", metavar="IFACE:CHANNEL", help="listen on this python-can bus, e.g. socketcan:can0")
    g.add_argument("--can-log", metavar="FILE",
                   help="read a log bsn-run --can-log wrote: .log (candump), .asc or .blf")
    g.add_argument("--serial", metavar="URL", help="listen on this serial port (pyserial URL)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (live inputs)")
    p.add_argument("--max", type=int, default=None, help="stop after this many frames")
    return p


class Printer:
    """Prints each decoded frame; counts bad CRCs, repeats and losses per message."""

    def __init__(self, out=None) -> None:
        self.out = out
        self.last: dict[str, int] = {}
        self.frames = self.bad_crc = self.lost = self.repeated = self.bad_lines = self.bad_fields = 0

    def __call__(self, frame_id: int, data: bytes, where: str = "") -> None:
        try:
            d = decode(frame_id, data)
        except Exception as e:  # a frame of our ids with the wrong length or layout
            self.bad_line(where or "frame", f"id {frame_id:#x} cannot be decoded ({type(e).__name__}: {e})")
            return
        if d is None:
            return
        self.frames += 1
        note = ""
        bad = invalid_fields(d)
        if bad and d.crc_ok:
            self.bad_fields += 1
            note = f"  (undefined {', '.join(bad)})"
        if not d.crc_ok:
            self.bad_crc += 1   # its counter cannot be trusted: the counter state stays
        elif not 0 <= d.counter < COUNTER_MOD:
            # outside the DBC's 0..14 (15 is 'invalid'): flagged, and no loss is counted from it
            self.bad_fields += 1
            note += f"  (counter {d.counter} outside 0-{COUNTER_MOD - 1})"
        else:
            prev = self.last.get(d.name)
            if prev == d.counter:
                self.repeated += 1
                note += "  (repeated)"
            else:
                gap = counter_gap(prev, d.counter)
                self.lost += gap
                note += f"  ({gap} lost)" if gap else ""
            self.last[d.name] = d.counter
        print(to_alert_text(d) + note, file=self.out or sys.stdout)

    def bad_line(self, where: str, why: str) -> None:
        self.bad_lines += 1
        print(f"{PROG}: {where}: {why}", file=sys.stderr)

    @property
    def ok(self) -> bool:
        """Nothing wrong: no bad CRC, repeat, loss, undefined field or unreadable line."""
        return not (self.bad_crc or self.repeated or self.lost or self.bad_fields or self.bad_lines)

    def summary(self) -> str:
        return (f"{self.frames} frames, {self.bad_crc} with a bad CRC, {self.lost} lost, {self.repeated} repeated, "
                f"{self.bad_fields} with an undefined field, {self.bad_lines} unreadable lines")


ECHO_CHARS = 60     # of a bad line or message echoed back: enough to recognise it, never a whole megabyte


def _short(text: str) -> str:
    return text if len(text) <= ECHO_CHARS else f"{text[:ECHO_CHARS]}... ({len(text)} characters)"


def candump_lines(path: Path, show: Printer) -> Iterator[tuple[int, bytes, str]]:
    """Frames of a candump log; comment, malformed and truncated lines are reported and skipped."""
    with open(path, errors="replace") as f:
        for n, line in enumerate(f, 1):
            text = line.strip()
            if not text or text.startswith(("#", ";")):
                if text:
                    show.bad_line(f"{path}:{n}", "comment line skipped")
                continue
            m = CANDUMP.match(text)
            if m is None:
                show.bad_line(f"{path}:{n}", f"not a candump line: {_short(text)!r}")
                continue
            payload = m.group(3)
            if len(payload) % 2 or len(payload) > 16:
                show.bad_line(f"{path}:{n}", f"truncated or oversized data {_short(payload)!r}")
                continue
            yield int(m.group(2), 16), bytes.fromhex(payload), f"{path}:{n}"


PYTHON_CAN_LOGS = (".asc", ".blf", ".csv", ".db", ".mf4", ".trc")


def python_can_log(path: Path, show: Printer) -> Iterator[tuple[int, bytes, str]]:
    import can

    try:
        reader = iter(can.LogReader(str(path)))
    except Exception as e:  # not a log of that kind at all: an unreadable file, as a damaged record is
        show.bad_line(str(path), f"unreadable ({type(e).__name__}: {_short(str(e))})")
        return
    while True:
        try:
            msg = next(reader)
        except StopIteration:
            return
        except Exception as e:  # a damaged record: python-can cannot go on after it
            show.bad_line(str(path), f"unreadable from here on ({type(e).__name__}: {_short(str(e))})")
            return
        yield msg.arbitration_id, bytes(msg.data), str(path)


class _Stopped(KeyboardInterrupt):
    """A terminating signal (TERM from a service manager, HUP from a closed terminal): listening ends as
    Ctrl-C ends it, with the summary."""


def _quiet() -> None:
    """The first signal decides: later ones, Ctrl-C included, change nothing while the summary is written."""
    if threading.current_thread() is threading.main_thread():
        for sig in (*STOP_SIGNALS, signal.SIGINT):
            signal.signal(sig, signal.SIG_IGN)


def _stop(signum: int, _frame: object) -> None:
    _quiet()
    raise _Stopped(signal.Signals(signum).name)


STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


def main(argv: list[str] | None = None) -> int:
    old = {}
    if threading.current_thread() is threading.main_thread():
        old = {signal.SIGINT: signal.getsignal(signal.SIGINT)}
        old |= {sig: signal.signal(sig, _stop) for sig in STOP_SIGNALS}
    try:
        return _listen(argv)
    finally:
        for sig, handler in old.items():
            if signal.getsignal(sig) is not signal.SIG_IGN:     # after a signal, a late one stays ignored
                signal.signal(sig, handler)


def _listen(argv: list[str] | None) -> int:
    args = build_parser().parse_args(argv)
    show = Printer()
    deadline = None if args.duration is None else time.monotonic() + args.duration

    def more() -> bool:
        return (args.max is None or show.frames < args.max) and (deadline is None or time.monotonic() < deadline)

    try:
        if args.can_log:
            path = Path(args.can_log)
            if not path.is_file():
                return fail(PROG, f"CAN log {path} not found")
            suffix = path.suffix.lower()
            if suffix != ".log" and suffix not in PYTHON_CAN_LOGS:
                return fail(PROG, f"{path}: not a CAN log this tool reads (.log, as bsn-run --can-log writes, or "
                                  f"python-can's {' '.join(PYTHON_CAN_LOGS)})")
            frames = candump_lines(path, show) if suffix == ".log" else python_can_log(path, show)
            for fid, data, where in frames:
                if not more():
                    break
                show(fid, data, where)
            if show.frames == 0 and not show.bad_lines:   # a run that sent nothing is not a clean run
                print(show.summary(), file=sys.stderr)
                return fail(PROG, f"{path}: holds no frame (bsn-run writes one every cycle from its start)", 1)
        elif args.can:
            import can
            iface, _, channel = args.can.partition(":")
            with can.Bus(interface=iface, channel=channel) as bus:
                while more():
                    msg = bus.recv(timeout=0.2)
                    if msg is not None:
                        show(msg.arbitration_id, bytes(msg.data))
        else:
            import serial
            dec = FrameDecoder()
            try:
                with serial.serial_for_url(args.serial, timeout=0.2) as port:
                    while more():
                        for fid, data in dec.feed(port.read(256)):
                            show(fid, data)
            finally:                  # SIGINT included: the frames whose CRC failed are counted
                show.bad_crc += dec.errors
    except KeyboardInterrupt:
        _quiet()
    except Exception as e:
        print(show.summary(), file=sys.stderr)
        return fail(PROG, f"{type(e).__name__}: {e}")
    print(show.summary(), file=sys.stderr)
    return 0 if show.ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
