"""``bsn-calibrate``: camera intrinsics and distortion from chessboard photos or a video."""

from __future__ import annotations

import argparse
import re

from tqdm import tqdm

from bsn_edge.calibration import calibrate
from bsn_edge.cli.common import fail

PROG = "bsn-calibrate"


def _board(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d+)[xX](\d+)", text.strip())
    if not m or min(int(m.group(1)), int(m.group(2))) < 2:
        raise argparse.ArgumentTypeError(f"board must be COLSxROWS inner corners, e.g. 9x6, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description="Calibrate a camera from views of a printed chessboard: "
                                "intrinsics fx fy cx cy, distortion k1 k2 p1 p2 k3 and the RMS reprojection "
                                "error, written as JSON for bsn-run --calib and bsn-label. Views where the "
                                "whole board is not found are skipped and listed with the reason.")
    p.add_argument("source", metavar="IMAGES_OR_VIDEO", help="folder of chessboard images, or a video")
    p.add_argument("--board", type=_board, default=(9, 6), help="inner corners, COLSxROWS (default 9x6)")
    p.add_argument("--square", type=float, default=0.025, help="square size in metres (default 0.025)")
    p.add_argument("--every", type=int, default=10, help="for a video: use every Nth frame (default 10)")
    p.add_argument("--out", required=True, help="output CALIB.json")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.square <= 0 or args.every < 1:
        return fail(PROG, "--square must be positive and --every >= 1")
    try:
        with tqdm(desc="views", unit="view", disable=None) as bar:
            cal = calibrate(args.source, args.board, args.square, args.every, progress=bar.update)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    cal.write(args.out)
    print(f"{len(cal.used)} views used, {len(cal.skipped)} skipped; RMS reprojection error {cal.rms_px:.3f} px")
    print(f"fx {cal.fx:.1f}  fy {cal.fy:.1f}  cx {cal.cx:.1f}  cy {cal.cy:.1f}  at {cal.height}x{cal.width} (H x W)")
    print("distortion k1 k2 p1 p2 k3: " + " ".join(f"{d:+.4f}" for d in cal.dist))
    for s in cal.skipped:
        print(f"  skipped {s['view']}: {s['reason']}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
