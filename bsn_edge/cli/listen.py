"""``bsn-listen``: decode and print what bsn-run sends, checking counters and CRCs."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from bsn_edge.alerts.bus_check import FrameChecker, Verdict
from bsn_edge.alerts.can_codec import STATUS, to_alert_text
from bsn_edge.alerts.can_log import PYTHON_CAN_LOGS, is_log, read_log
from bsn_edge.alerts.dbc import BusLayout, bus_layout
from bsn_edge.alerts.e2e import COUNTER_MOD
from bsn_edge.alerts.serial_codec import FrameDecoder
from bsn_edge.cli.common import fail

PROG = "bsn-listen"
# the status goes out at least once a second whatever the rates (the DBC says so): longer is a silent bus
STATUS_SILENCE_S = 1.5


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description="Decode bsn-run's alerts from a CAN bus, a CAN log or a "
                                "serial port, with the decoders the tests use; report CRC mismatches, repeated and "
                                "lost frames, and log lines that cannot be read. Exit code 1 when anything was wrong.")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--can", metavar="IFACE:CHANNEL", help="listen on this python-can bus, e.g. socketcan:can0")
    g.add_argument("--can-log", metavar="FILE",
                   help="read a log bsn-run --can-log wrote: .log (candump), .asc or .blf")
    g.add_argument("--serial", metavar="URL", help="listen on this serial port (pyserial URL)")
    g.add_argument("--udp", metavar="[HOST:]PORT",
                   help="listen for bsn-run's UDP datagrams (bsn-run --output udp:HOST:PORT) on this port, of every "
                        "address unless HOST is given")
    p.add_argument("--config", metavar="FILE",
                   help="the vehicle file bsn-run ran with: its [sectors] layout says which sectors the hazard frames "
                        "carry (default: LEFT, CENTRE, RIGHT, the shipped DBC)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (live inputs)")
    p.add_argument("--max", type=int, default=None, help="stop after this many frames")
    p.add_argument("--onsets", action="store_true",
                   help="with --can-log: print only the level onsets, in bsn-report's form (seconds into the log, "
                        "sector, level, the hazard frame's number), as the report matches them with the frame log")
    return p


def print_onsets(path: Path, sectors: tuple[str, ...] | None = None) -> int:
    """``--onsets``: each level rise the log's trusted hazard frames carry (``sectors``: the layout's), one a
    line; damage counted below."""
    from bsn_edge.alerts.bus_onsets import read_bus

    bus = read_bus(path, sectors)
    print(f"{'at':>10}  {'sector':<8} {'level':<8} hazard frame in the log")
    for o in bus.onsets:
        print(f"{o.timestamp - bus.start:>8.2f} s  {o.sector:<8} {o.level:<8} {o.frame}")
    damaged = ", ".join(f"{n} {k}" for k, n in bus.damaged.items())
    print(f"{len(bus.onsets)} onsets in {bus.hazard_frames} hazard frames"
          + (f"; damaged: {damaged}" if damaged else "") + (f"; {bus.unreadable}" if bus.unreadable else ""),
          file=sys.stderr)
    return 1 if damaged or bus.unreadable else 0


class Printer:
    """Prints each decoded frame as :class:`FrameChecker` judges it; counts bad CRCs, repeats, losses,
    undefined fields and unreadable lines (each frame under one verdict)."""

    def __init__(self, out=None, layout: BusLayout | None = None) -> None:
        self.out = out
        self.check = FrameChecker(layout=layout)
        self.frames = self.bad_lines = self.gaps = 0
        self.serial_crc = 0        # frames the serial decoder dropped for a bad CRC before decoding
        self.first_t: float | None = None
        self.last_status_t: float | None = None

    @property
    def bad_crc(self) -> int:
        return self.check.counts[Verdict.BAD_CRC] + self.serial_crc

    @property
    def repeated(self) -> int:
        return self.check.counts[Verdict.REPEATED]

    @property
    def lost(self) -> int:
        return self.check.lost

    @property
    def bad_fields(self) -> int:
        return self.check.counts[Verdict.UNDEFINED] + self.check.counts[Verdict.BAD_COUNTER]

    def __call__(self, frame_id: int, data: bytes, where: str = "", t: float | None = None) -> None:
        """Judge and print one frame; ``t``: its time (the log's or the receiver's clock), printed from the
        first frame's and checked for silences on the bus."""
        c = self.check(frame_id, data)
        if c is None:
            return
        if c.decoded is None:
            self.bad_line(where or "frame", f"id {frame_id:#x} cannot be decoded ({c.detail})")
            return
        self.frames += 1
        note = {Verdict.OK: "", Verdict.BAD_CRC: "", Verdict.REPEATED: "  (repeated)",
                Verdict.UNDEFINED: f"  (undefined {c.detail})",
                Verdict.BAD_COUNTER: f"  ({c.detail} outside 0-{COUNTER_MOD - 1})"}.get(c.verdict, "")
        note += f"  ({c.lost} lost)" if c.lost else ""
        stamp = ""
        if t is not None:
            self.first_t = t if self.first_t is None else self.first_t
            stamp = f"{t - self.first_t:9.3f} s  "
            if c.decoded.name == STATUS:
                if self.last_status_t is not None and t - self.last_status_t > STATUS_SILENCE_S:
                    self.gaps += 1
                    note += f"  (the bus was silent {t - self.last_status_t:.2f} s)"
                self.last_status_t = t
        print(stamp + to_alert_text(c.decoded, c.number) + note, file=self.out or sys.stdout)

    def bad_line(self, where: str, why: str) -> None:
        self.bad_lines += 1
        print(f"{PROG}: {where}: {why}", file=sys.stderr)

    @property
    def ok(self) -> bool:
        """Nothing wrong: no bad CRC, repeat, loss, undefined field, silence or unreadable line."""
        return not (self.bad_crc or self.repeated or self.lost or self.bad_fields or self.bad_lines or self.gaps)

    def summary(self) -> str:
        return (f"{self.frames} frames, {self.bad_crc} with a bad CRC, {self.lost} lost, {self.repeated} repeated, "
                f"{self.bad_fields} with an undefined field, {self.gaps} silences over {STATUS_SILENCE_S:g} s, "
                f"{self.bad_lines} unreadable lines")


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


def _sectors(config: str | None) -> tuple[str, ...] | None:
    """The sectors of the vehicle file at ``config`` (None without one: the default layout)."""
    if config is None:
        return None
    from bsn_edge.runtime.config_file import load_runtime_config

    return load_runtime_config(config).sectors.names


def _listen_udp(where: str, show: Printer, more: Callable[[], bool]) -> None:
    """Every frame of the datagrams that reach ``[HOST:]PORT``, judged; a datagram of another layout is an
    unreadable line, counted."""
    import socket

    from bsn_edge.alerts.udp_output import udp_frames

    host, _, port = where.rpartition(":")
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--udp {where!r}: give [HOST:]PORT, e.g. 9000 or 127.0.0.1:9000")
    with socket.socket(socket.AF_INET6 if ":" in host.strip("[]") else socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind((host.strip("[]") or "", int(port)))
        rx.settimeout(0.2)
        n = 0
        while more():
            try:
                datagram = rx.recv(65536)
            except TimeoutError:
                continue
            n += 1
            try:
                frames = udp_frames(datagram)
            except ValueError as e:
                show.bad_line(f"datagram {n}", str(e))
                continue
            for _, fid, data in frames:
                show(fid, data, t=time.monotonic())


def _listen(argv: list[str] | None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    if args.onsets and not args.can_log:
        p.error("--onsets reads a CAN log: give --can-log FILE")
    try:
        sectors = _sectors(args.config)
    except (ValueError, OSError) as e:
        return fail(PROG, str(e))
    show = Printer(layout=bus_layout(sectors))
    deadline = None if args.duration is None else time.monotonic() + args.duration

    def more() -> bool:
        return (args.max is None or show.frames < args.max) and (deadline is None or time.monotonic() < deadline)

    try:
        if args.can_log:
            path = Path(args.can_log)
            if not path.is_file():
                return fail(PROG, f"CAN log {path} not found")
            if not is_log(path):
                return fail(PROG, f"{path}: not a CAN log this tool reads (.log, as bsn-run --can-log writes, or "
                                  f"python-can's {' '.join(PYTHON_CAN_LOGS)})")
            if args.onsets:
                return print_onsets(path, sectors)
            for f in read_log(path, show.bad_line):
                if not more():
                    break
                show(f.frame_id, f.data, f.where, f.timestamp)
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
                        show(msg.arbitration_id, bytes(msg.data), t=time.monotonic())
        elif args.udp:
            _listen_udp(args.udp, show, more)
        else:
            import serial
            dec = FrameDecoder()
            try:
                with serial.serial_for_url(args.serial, timeout=0.2) as port:
                    while more():
                        for fid, data in dec.feed(port.read(256)):
                            show(fid, data, t=time.monotonic())
            finally:                  # SIGINT included: the frames whose CRC failed are counted
                show.serial_crc += dec.errors
    except KeyboardInterrupt:
        _quiet()
    except Exception as e:
        print(show.summary(), file=sys.stderr)
        return fail(PROG, f"{type(e).__name__}: {e}")
    print(show.summary(), file=sys.stderr)
    return 0 if show.ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
