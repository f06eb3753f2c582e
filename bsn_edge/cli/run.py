"""``bsn-run``: dashcam video in, left / centre / right hazard levels out."""

from __future__ import annotations

import argparse
import json
import sys

from tqdm import tqdm

from bsn_edge.alerts.senders import CanSender, Sender, SerialSender
from bsn_edge.calibration.chessboard import Calibration
from bsn_edge.cli.common import fail
from bsn_edge.runtime import Engine, RuntimeConfig, open_source, run

PROG = "bsn-run"
LOG_CHANNEL = "bsn-can-log"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Run the fused blind-spot model on a video file, an image folder, a camera or a stream: "
                    "per frame blind-spot mask and depth -> LEFT / CENTRE / RIGHT sectors -> smoothing -> "
                    "alert state -> CAN and/or serial at a fixed cycle, with a status heartbeat. Prints a "
                    "summary (frames, dropped, frames/s, p50/p95/p99 latency, per-stage shares).")
    p.add_argument("--model", required=True, help="fused ONNX model from bsn-export")
    p.add_argument("--source", required=True, help="VIDEO file, image DIR, CAMERA_INDEX or stream URL")
    p.add_argument("--can", metavar="IFACE:CHANNEL", help="send on this python-can bus, e.g. socketcan:can0")
    p.add_argument("--can-log", metavar="FILE.log",
                   help="log every CAN frame sent: .log (candump format, readable by python -m cantools decode), "
                        ".asc or .blf; without --can, frames go to a virtual bus")
    p.add_argument("--serial", metavar="URL", help="send on this serial port (pyserial URL, e.g. /dev/ttyUSB0)")
    p.add_argument("--overlay", metavar="OUT.mp4", help="write a video with blind spots and sector levels")
    p.add_argument("--log", metavar="OUT.jsonl", help="one JSON line per frame")
    p.add_argument("--max-frames", type=int, default=None, metavar="N", help="stop after this many frames")
    p.add_argument("--threads", type=int, default=2, help="onnxruntime intra-op threads (default 2)")
    p.add_argument("--no-spin", action="store_true", help="do not let idle onnxruntime threads spin")
    p.add_argument("--pace", action="store_true", help="play files at their own frame rate")
    p.add_argument("--cycle", type=float, default=0.1, help="send cycle in seconds (default 0.1)")
    p.add_argument("--summary", metavar="OUT.json", help="also write the summary here")
    p.add_argument("--calib", metavar="CALIB.json",
                   help="camera calibration from bsn-calibrate: its intrinsics replace the model's, and frames "
                        "are undistorted first")
    return p


def make_senders(args) -> list[Sender]:
    senders: list[Sender] = []
    if args.can_log:
        from pathlib import Path
        Path(args.can_log).parent.mkdir(parents=True, exist_ok=True)
    if args.can or args.can_log:
        iface, _, channel = (args.can or f"virtual:{LOG_CHANNEL}").partition(":")
        if not channel:
            raise ValueError(f"--can needs IFACE:CHANNEL, got {args.can!r}")
        senders.append(CanSender(iface, channel, log_path=args.can_log))
    if args.serial:
        senders.append(SerialSender(args.serial))
    return senders


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.max_frames is not None and args.max_frames < 1:
        return fail(PROG, "--max-frames must be >= 1")
    try:
        engine = Engine(args.model, args.threads, not args.no_spin)
        source = open_source(args.source, pace=args.pace)
        calibration = Calibration.read(args.calib) if args.calib else None
        senders = make_senders(args)
    except (FileNotFoundError, ValueError, OSError) as e:
        return fail(PROG, str(e))
    except Exception as e:  # python-can / pyserial open errors
        return fail(PROG, f"cannot open the output: {type(e).__name__}: {e}")
    try:
        total = args.max_frames or getattr(source, "total", None) or (len(source.files) if hasattr(source, "files")
                                                                        else None)
        with tqdm(total=total, unit="frame", desc="bsn-run", disable=None, file=sys.stderr) as bar:
            summary = run(engine, source, senders, RuntimeConfig(cycle_s=args.cycle), overlay=args.overlay,
                          log=args.log, max_frames=args.max_frames, progress=bar.update, calibration=calibration)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    finally:
        source.close()
        for s in senders:
            s.close()
    text = json.dumps(summary, indent=1)
    if args.summary:
        with open(args.summary, "w") as f:
            f.write(text + "\n")
    print(text)
    for s in senders:
        if s.stats.errors:
            print(f"{PROG}: warning: {s.name} failed {s.stats.errors} times ({s.stats.last_error})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
