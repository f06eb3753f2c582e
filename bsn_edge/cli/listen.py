"""``bsn-listen``: decode and print what bsn-run sends, checking counters and CRCs."""

from __future__ import annotations

import argparse
import sys
import time

from bsn_edge.alerts.can_codec import decode, to_alert_text
from bsn_edge.alerts.e2e import counter_gap
from bsn_edge.alerts.serial_codec import FrameDecoder
from bsn_edge.cli.common import fail

PROG = "bsn-listen"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description="Decode bsn-run's alerts from a CAN bus, a CAN log "
                                "(.asc/.blf) or a serial port, with the decoders the tests use; report CRC "
                                "mismatches and lost frames.")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--can", metavar="IFACE:CHANNEL")
    g.add_argument("--can-log", metavar="FILE")
    g.add_argument("--serial", metavar="URL")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (live inputs)")
    p.add_argument("--max", type=int, default=None, help="stop after this many frames")
    return p


class Printer:
    def __init__(self, out=None) -> None:
        self.out, self.last = out, {}
        self.frames = self.bad_crc = self.lost = 0

    def __call__(self, frame_id: int, data: bytes) -> None:
        d = decode(frame_id, data)
        if d is None:
            return
        self.frames += 1
        self.bad_crc += not d.crc_ok
        gap = counter_gap(self.last.get(d.name), d.counter)
        self.lost += gap
        self.last[d.name] = d.counter
        print(to_alert_text(d) + (f"  ({gap} lost)" if gap else ""), file=self.out or sys.stdout)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    show = Printer()
    deadline = None if args.duration is None else time.monotonic() + args.duration

    def more() -> bool:
        return (args.max is None or show.frames < args.max) and (deadline is None or time.monotonic() < deadline)

    try:
        if args.can_log:
            import can
            for msg in can.LogReader(args.can_log):
                if not more():
                    break
                show(msg.arbitration_id, bytes(msg.data))
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
            with serial.serial_for_url(args.serial, timeout=0.2) as port:
                while more():
                    for fid, data in dec.feed(port.read(256)):
                        show(fid, data)
            show.bad_crc += dec.errors
    except FileNotFoundError as e:
        return fail(PROG, str(e))
    except KeyboardInterrupt:
        pass
    except Exception as e:
        return fail(PROG, f"{type(e).__name__}: {e}")
    print(f"{show.frames} frames, {show.bad_crc} with a bad CRC, {show.lost} lost", file=sys.stderr)
    return 0 if show.bad_crc == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
