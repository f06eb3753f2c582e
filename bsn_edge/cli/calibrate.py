"""``bsn-calibrate``: camera intrinsics and distortion from chessboard photos or a video, and the
camera's mounting from a short straight drive (``--mount``)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from bsn_edge.calibration import Calibration, calibrate
from bsn_edge.calibration.field_of_view import WIDE_DEG, from_field_of_view
from bsn_edge.calibration.mount_fit import MountFitConfig
from bsn_edge.calibration.mounting_step import MountingRefusedError, calibrate_mounting, check_arguments
from bsn_edge.cli.common import fail
from bsn_edge.progress import progress_bar

PROG = "bsn-calibrate"


def _board(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d+)[xX](\d+)", text.strip())
    if not m or min(int(m.group(1)), int(m.group(2))) < 2:
        raise argparse.ArgumentTypeError(f"board must be COLSxROWS inner corners, e.g. 9x6, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description="Calibrate a camera. Step 1, from views of a printed "
                                "chessboard: intrinsics fx fy cx cy, distortion k1 k2 p1 p2 k3 and the RMS "
                                "reprojection error (views where the whole board is not found are skipped and "
                                "listed). Step 2, --mount, from a short straight drive: pitch and yaw from the focus "
                                "of expansion, roll from the road plane, the height measured (--height) or from a "
                                "known lane width (--lane-width); each with its spread, or a refusal with reasons "
                                "(turning, standing still, too short). Both write the camera file that bsn-run "
                                "--calib and bsn-label --calib read. No chessboard: --hfov gives step 1 from the "
                                "camera's horizontal field of view (its specification), without lens distortion.")
    p.add_argument("source", metavar="IMAGES_OR_VIDEO",
                   help="folder of chessboard images or a video of a chessboard; with --hfov, any video of the "
                        "camera (or a folder of its frames); with --mount, a driving video")
    p.add_argument("--board", type=_board, default=(9, 6), help="inner corners, COLSxROWS (default 9x6)")
    p.add_argument("--square", type=float, default=0.025, help="square size in metres (default 0.025)")
    p.add_argument("--every", type=int, default=10, help="for a video: use every Nth frame (default 10)")
    p.add_argument("--hfov", type=float, metavar="DEG",
                   help="no chessboard: the camera's horizontal field of view in degrees (from its data sheet); "
                        "writes a pinhole camera at the frames' size, without lens distortion (rough above "
                        f"{WIDE_DEG:g} degrees)")
    p.add_argument("--out", required=True, help="output CALIB.json (refused if it exists, unless --force)")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    m = p.add_argument_group("mounting (--mount)")
    m.add_argument("--mount", action="store_true", help="estimate the mounting from a driving video")
    m.add_argument("--calib", metavar="INTRINSICS.json", help="the camera file with the intrinsics (step 1)")
    m.add_argument("--height", type=float, metavar="M", help="camera height above the road, measured, in metres")
    m.add_argument("--lane-width", type=float, metavar="M",
                   help="width of the lanes driven in, marking centre to marking centre (e.g. 3.7 on a US "
                        "highway): the height is estimated from it")
    m.add_argument("--max-error", type=float, default=MountFitConfig.max_spread_deg, metavar="DEG",
                   help="accept the pitch and yaw once their standard error over the clip is at most this "
                        f"(default {MountFitConfig.max_spread_deg})")
    m.add_argument("--max-frames", type=int, default=None, metavar="N", help="use at most this many frames")
    return p


def mount(args) -> int:
    if not args.calib:
        return fail(PROG, "--mount needs --calib INTRINSICS.json (run the chessboard step first)")
    try:
        check_arguments(args.height, args.lane_width)
    except ValueError as e:
        return fail(PROG, str(e))
    try:
        camera = Calibration.read(args.calib)
        with progress_bar(desc="frames", unit="frame") as bar:
            cal = calibrate_mounting(args.source, camera, args.height, args.lane_width,
                                     MountFitConfig(max_spread_deg=args.max_error), max_frames=args.max_frames,
                                     progress=bar.update)
    except MountingRefusedError as e:
        hint = (f"; or accept a looser estimate with --max-error {2 * args.max_error:g}"
                if "not settled" in str(e) else "")
        return fail(PROG, f"cannot estimate the mounting from {args.source}: {e}{hint}")
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    cal.write(args.out)
    m, r = cal.mounting, cal.mounting_report
    assert m is not None and cal.hood is not None     # the mounting step gives both, or raises
    sp = r["spread_deg"]
    se = r["standard_error_deg"]
    print(f"{r['used']} of {r['pairs']} frame pairs used ({r['method']}); standard error pitch {se['pitch']:.2f}, "
          f"yaw {se['yaw']:.2f} degrees")
    print(f"pitch {m.pitch_deg:+.2f} (spread {sp['pitch']:.2f})  yaw {m.yaw_deg:+.2f} (spread {sp['yaw']:.2f})  "
          f"roll {m.roll_deg:+.2f} degrees" + (f" (spread {sp['roll']:.2f})" if sp["roll"] is not None else
                                              " (road plane not seen: 0 assumed)"))
    hr = r["height"]
    print(f"height {m.height_m:.2f} m ({hr['method']}" + (f", spread {hr['spread_m']:.2f} m)" if "spread_m" in hr
                                                           else ")"))
    print(f"hood: {cal.hood.describe()}")
    print(f"wrote {args.out}")
    return 0


def field_of_view(args) -> int:
    try:
        cal = from_field_of_view(args.source, args.hfov)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    cal.write(args.out)
    k = cal.intrinsics
    print(f"fx {k.fx:.1f}  fy {k.fy:.1f}  cx {k.cx:.1f}  cy {k.cy:.1f}  at {k.width}x{k.height} "
          f"(width x height), from {args.hfov:g} degrees across; no lens distortion")
    if args.hfov > WIDE_DEG:
        print(f"{PROG}: note: a lens {args.hfov:g} degrees across bends straight lines towards its edges, which a "
              "field of view cannot say; the chessboard step measures it", file=sys.stderr)
    print(f"wrote {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if Path(args.out).exists() and not args.force:
        return fail(PROG, f"{args.out} exists; pass --force to overwrite it")
    if args.mount:
        if args.hfov is not None:
            return fail(PROG, "--hfov is step 1 (the intrinsics) and --mount step 2: write the camera file with "
                              "--hfov first, then pass it to --mount with --calib")
        return mount(args)
    if args.hfov is not None:
        return field_of_view(args)
    if args.square <= 0 or args.every < 1:
        return fail(PROG, "--square must be positive and --every >= 1")
    try:
        with progress_bar(desc="views", unit="view") as bar:
            cal = calibrate(args.source, args.board, args.square, args.every, progress=bar.update)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    cal.write(args.out)
    print(f"{len(cal.used)} views used, {len(cal.skipped)} skipped; RMS reprojection error {cal.rms_px:.3f} px")
    k = cal.intrinsics
    print(f"fx {k.fx:.1f}  fy {k.fy:.1f}  cx {k.cx:.1f}  cy {k.cy:.1f}  at {k.width}x{k.height} "
          "(width x height)")
    print("distortion k1 k2 p1 p2 k3: " + " ".join(f"{d:+.4f}" for d in cal.dist))
    for s in cal.skipped:
        print(f"  skipped {s['view']}: {s['reason']}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
