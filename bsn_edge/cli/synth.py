"""``bsn-synth``: render a synthetic driving clip into a sequence folder."""

from __future__ import annotations

import argparse
import os
import time

from bsn_edge.cli.common import fail, glue_values, parse_size
from bsn_edge.progress import progress_bar
from bsn_edge.synth import STYLES, SynthConfig, write_clip
from bsn_edge.synth.clip import check_output

PROG = "bsn-synth"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Render a clip of the synthetic driving world: RGB, exact depth, Cityscapes "
                    "semantics, camera poses and true blind spots, written as a sequence folder "
                    "(meta.json, poses.txt, rgb/, depth/, semantic/, bsgt/, boxes/, video.mp4).",
    )
    p.add_argument("out", help="output sequence folder (must not exist or be empty, unless --force)")
    p.add_argument("--frames", type=int, default=200, help="number of frames (default 200)")
    p.add_argument("--size", type=parse_size, default=(256, 512), metavar="HxW",
                   help="image size, height x width (default 256x512)")
    p.add_argument("--fps", type=float, default=10.0, help="frame rate (default 10)")
    p.add_argument("--style", choices=sorted(STYLES), default="town",
                   help="scene style: town (dense, narrow), suburb (open, wide, hedges and fences), highway "
                        "(multi-lane, barriers, few buildings, 20-28 m/s) or urban (tall blocks, parked cars on "
                        "both curbs, narrow lanes, crowds); default town")
    p.add_argument("--seed", type=int, default=0, help="random seed; same seed, same bytes (default 0)")
    p.add_argument("--parked", type=float, default=1.0, help="parked-vehicle density multiplier")
    p.add_argument("--traffic", type=float, default=1.0, help="moving-traffic density multiplier")
    p.add_argument("--pedestrians", type=float, default=1.0, help="pedestrian density multiplier")
    p.add_argument("--lead", type=float, default=SynthConfig.lead,
                   help="probability that the clip follows 1-3 vehicles in its own lane, 0.3-2 s ahead "
                        f"plus 2-5 m (default {SynthConfig.lead}; 0: never; none with --traffic 0)")
    p.add_argument("--queue", type=float, default=SynthConfig.queue,
                   help="probability that the clip creeps in slow traffic at 1.5-4 m/s behind such vehicles, "
                        f"the nearest 4-15 m from the camera (default {SynthConfig.queue}; 0: never)")
    p.add_argument("--range", dest="bs_range", type=float, default=50.0,
                   help="true blind spots count within this ground distance, metres (default 50)")
    p.add_argument("--camera", choices=("vary", "fixed"), default="vary",
                   help="vary (default): the clip draws its own camera from its seed: field of view 50-110 "
                        "degrees, height 1.1-1.9 m, a few degrees of pitch, yaw and roll, barrel distortion on "
                        "some, the car's hood on some (written to calibration.json). fixed: the 80-degree, 1.5 m "
                        "camera of earlier versions")
    p.add_argument("--no-sensor-effects", action="store_true",
                   help="plain 8-bit frames: no motion blur, defocus, noise, tone curve, vignetting or JPEG")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="processes that render (default: up to 2); the bytes do not depend on it")
    p.add_argument("--no-video", action="store_true", help="skip writing video.mp4")
    p.add_argument("--force", action="store_true", help="overwrite an existing sequence folder")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(glue_values(argv))
    h, w = args.size
    try:
        cfg = SynthConfig(frames=args.frames, height=h, width=w, fps=args.fps, style=args.style,
                          seed=args.seed, camera=args.camera, parked=args.parked, traffic=args.traffic,
                          pedestrians=args.pedestrians, lead=args.lead, queue=args.queue, bs_range=args.bs_range,
                          sensor_effects=not args.no_sensor_effects)
    except ValueError as e:
        return fail(PROG, str(e))
    try:
        check_output(args.out, args.force)            # before the progress line: a refusal is all it prints
    except FileExistsError as e:
        return fail(PROG, str(e))
    t0 = time.perf_counter()
    try:
        with progress_bar(total=cfg.frames, desc=f"render {args.out}", unit="frame") as bar:
            out = write_clip(cfg, args.out, force=args.force, video=not args.no_video, progress=bar.update,
                             workers=max(1, args.workers))
    except (FileExistsError, OSError, ValueError) as e:
        return fail(PROG, str(e))
    dt = time.perf_counter() - t0
    print(f"{out}: {cfg.frames} frames of {cfg.style} at {h}x{w}, {cfg.fps:g} fps, seed {cfg.seed} "
          f"in {dt:.1f} s ({cfg.frames / dt:.1f} frames/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
