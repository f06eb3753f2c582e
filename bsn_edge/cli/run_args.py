"""``bsn-run``'s command line: its options in groups (the model and the source, the camera, the outputs, the
settings, speed on the car's cores). Standard library only at the top, as ``bsn-run``'s own module."""

from __future__ import annotations

import argparse
import sys

from bsn_edge.cli.run_report import PROG
from bsn_edge.default_model import DEFAULT_MODEL

CAN_LOG_EXTS = (".log", ".asc", ".blf")   # what python-can writes and bsn-listen reads back
OVERLAY_EXTS = (".mp4", ".avi", ".mov", ".mkv")   # what OpenCV's mp4v writer fills


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Run the fused blind-spot model on a video file, an image folder, a camera or a stream: "
                    "per frame blind-spot mask and depth -> the vehicle file's sectors (LEFT / CENTRE / RIGHT by "
                    "default) -> smoothing -> "
                    "alert state -> CAN and/or serial at a fixed cycle, with a status heartbeat. Prints a "
                    "summary (frames, dropped, frames/s, p50/p95/p99 latency, per-stage shares). Before the "
                    "first frame the model's digest, signature and self-test are checked: a model that fails "
                    "them is refused (UNAVAILABLE is sent first); only models signed by a trusted key run, "
                    "unless --allow-unsigned. Exit codes: 0 done (or stopped by SIGTERM, as a service "
                    "manager stops it), 1 the source failed, 2 could not start, 128 + N stopped by signal N "
                    "(130 SIGINT, 129 SIGHUP, 131 SIGQUIT). A signal at any moment, start-up included, and any "
                    "later ones end the run the same way: UNAVAILABLE last on every bus, the summary written.")
    _model_and_source(p)
    _camera(p)
    _outputs(p)
    _settings(p)
    _speed(p)
    return p


def _model_and_source(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("what runs on what")
    g.add_argument("--model", default=str(DEFAULT_MODEL),
                   help="fused ONNX model from bsn-export (default: the shipped one, inside the package, signed "
                        "with the project's key)")
    g.add_argument("--source", required=True, help="VIDEO file, image DIR, CAMERA_INDEX or stream URL")
    g.add_argument("--trust", metavar="KEYS", action="append", default=[],
                   help="also trust models signed by these Ed25519 public keys: a .pub file, a file of several or a "
                        "folder (repeatable). Always trusted: the project's key (the shipped models) and the keys in "
                        "your trust folder ($BSN_EDGE_TRUST, else ~/.config/bsn-edge/trust). A model signed by none "
                        "of them is refused")
    g.add_argument("--allow-unsigned", action="store_true",
                   help="run a model that is unsigned or signed by a key not trusted here (your own experiments); "
                        "the status then says Model_Unsigned on every cycle and the summary says whose it is not. "
                        "A signature that does not match its model is refused even so")
    g.add_argument("--pace", action="store_true", help="play a video file at its own frame rate, a folder at 10 "
                   "pictures a second (else as fast as the model runs)")
    g.add_argument("--stall", type=float, default=None, metavar="SECONDS",
                   help="a camera or stream that delivers no frame for this long is lost: the bus says "
                        "UNAVAILABLE and it is reopened with back-off (source.stall_s; default 2)")
    g.add_argument("--max-frames", type=int, default=None, metavar="N", help="stop after this many frames")


def _camera(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("the camera")
    g.add_argument("--calib", metavar="CALIB.json",
                   help="the camera file from bsn-calibrate (intrinsics, lens distortion and, after --mount, the "
                        "mounting): every frame is warped into the model's own camera with it. Without a mounting "
                        "in it, the camera is calibrated online (status CALIBRATING until pitch and yaw have "
                        "converged over forward driving). Without --calib the camera is taken to be the model's "
                        "own, rescaled, and calibrated online")
    g.add_argument("--height", type=float, metavar="M",
                   help="camera height above the road in metres (overrides the camera file's; default: the "
                        "file's, else the model camera's reference height). Distances scale with it")
    g.add_argument("--save-calib", metavar="CALIB.json",
                   help="where online calibration writes the camera file once it has converged (refuses an "
                        "existing file unless --force)")


def _outputs(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("where the alerts and the rest go")
    g.add_argument("--can", metavar="IFACE:CHANNEL",
                   help="send on this python-can bus, e.g. socketcan:can0 (bus.can in --config; its timeouts and "
                        "each message's rate are there too)")
    g.add_argument("--can-log", metavar="FILE.log",
                   help="log every CAN frame sent: .log (candump format, readable by python -m cantools decode), "
                        ".asc or .blf; without --can, frames go to a virtual bus")
    g.add_argument("--serial", metavar="URL",
                   help="send on this serial port (pyserial URL, e.g. /dev/ttyUSB0; bus.serial in --config, its baud "
                        "rate bus.serial_baud, default 115200)")
    g.add_argument("--output", action="append", default=[], metavar="SCHEME:TARGET",
                   help="one more output, repeatable: udp:HOST:PORT (the bus's frames in UDP datagrams, for a "
                        "driving stack on a PC; docs/protocol.md), can:IFACE:CHANNEL, serial:URL; added to "
                        "bus.outputs in --config")
    g.add_argument("--cycle", type=float, default=None,
                   help="send cycle in seconds (default 0.1; runtime.cycle_s in --config)")
    g.add_argument("--overlay", metavar="OUT.mp4",
                   help="write a video with blind spots and sector levels (drawn on a thread of its own: from a "
                        "camera, frames it falls behind on are left out of it and counted, never the alerts)")
    g.add_argument("--log", metavar="OUT.jsonl", help="one JSON line per frame")
    g.add_argument("--summary", metavar="OUT.json", help="also write the summary here")
    g.add_argument("--profile", metavar="DIR",
                   help="latency and CPU profiling in one command: a file or folder played at its own rate "
                        "(--pace), at most 300 frames unless --max-frames says otherwise (about 12 s of a 25 "
                        "frames/s video), the frame log and the summary written into DIR (frames.jsonl, "
                        "summary.json), and each stage's milliseconds a frame, CPU per frame and its share of the "
                        "cores in the end lines; bsn-report DIR/frames.jsonl --summary DIR/summary.json --out "
                        "DIR/report then draws the page (p50/p95/p99 per stage, a histogram)")
    g.add_argument("--save-maps", metavar="DIR",
                   help="per frame, NAME_blindspot.png (8-bit probability) and NAME_depth.png (16-bit, metres x "
                        "256, 0 = none) in the raw frame's own pixels, NAME the image's stem or the frame number; "
                        "a folder that already holds maps is refused unless --force")
    g.add_argument("--force", action="store_true",
                   help="replace existing output files (--overlay, --log, --summary, --can-log, --save-calib) and "
                        "let --save-maps write over an earlier run's maps; without it they are refused before the "
                        "first frame. Missing folders are made")


class _PrintDefaults(argparse.Action):
    """``--print-config`` / ``--print-schema``: the packaged settings file, or its JSON Schema, on standard
    output, then exit (as ``--help``)."""

    def __init__(self, option_strings: list[str], dest: str, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        from bsn_edge.runtime.config_file import SCHEMA_FILE, with_ranges
        sys.stdout.write(SCHEMA_FILE.read_text(encoding="utf-8") if option_string == "--print-schema"
                         else with_ranges())
        parser.exit()


def _settings(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("the runtime's settings (sectors, smoothing, levels, health, the cycle)")
    g.add_argument("--config", metavar="RUNTIME.toml",
                   help="the runtime's settings in one file (--print-config prints one with each at its default and "
                        "what it does, to copy and edit); the summary holds the resolved settings and their digest")
    g.add_argument("--print-config", action=_PrintDefaults,
                   help="print the runtime's settings file, every setting at its default with what it does and its "
                        "range, and exit (it ships inside the package; configs/runtime.toml in a checkout)")
    g.add_argument("--print-schema", action=_PrintDefaults,
                   help="print the JSON Schema of that file (types, ranges, defaults, what each does; "
                        "configs/runtime.schema.json in a checkout) and exit; docs/settings.md is its reference")
    g.add_argument("--print-dbc", action="store_true",
                   help="print the DBC of the bus for the settings' [sectors] layout (with --config and --set; "
                        "without them, the shipped bsn_edge/alerts/bsn_alerts.dbc) and exit: the file a receiver "
                        "decodes this vehicle's frames with")
    g.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="change one setting, after --config: e.g. --set alerts.tau_s=0.5 --set "
                        "alerts.warning.on=0.7 (repeatable). --cycle, --in-flight, "
                        "--in-turn, --threads, --spin / --no-spin and --stall are shorthands for runtime.cycle_s, "
                        "runtime.in_flight, runtime.overlap, runtime.threads, runtime.spin and source.stall_s")


def _speed(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("speed on the car's cores")
    g.add_argument("--threads", type=int, default=None,
                   help="onnxruntime intra-op threads per inference (runtime.threads; default 2, or 1 with "
                        "--in-flight 2 and more)")
    g.add_argument("--in-flight", type=int, default=None, metavar="N",
                   help="frames the model runs at once, each on a thread of its own (default 1). On 2 cores, 2 "
                        "gives more frames a second than one inference split over both, each frame's answer "
                        "later (see the README); needs reading overlapped")
    spin = g.add_mutually_exclusive_group()
    spin.add_argument("--spin", action="store_true",
                      help="let idle onnxruntime threads spin-wait (runtime.spin; faster for the model alone, slower "
                           "end to end: they take the cores the loop decodes, warps and calibrates on)")
    spin.add_argument("--no-spin", action="store_true", help="idle onnxruntime threads sleep (the default)")
    reading = g.add_mutually_exclusive_group()
    reading.add_argument("--overlap", action="store_true",
                         help="decode and warp the next frame on a thread of its own, at a lower priority, while "
                              "the model runs (the default; see the README)")
    reading.add_argument("--in-turn", action="store_true",
                         help="read each frame after the model has answered the one before (one thread)")
