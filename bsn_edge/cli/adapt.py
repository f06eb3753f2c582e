"""``bsn-adapt``: adapt a trained run to your own camera and roads from unlabelled video."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from bsn_edge.adapt.config import ASSUMED_HEIGHT_M, LABEL_DEPTHS, AdaptConfig
from bsn_edge.cli.common import fail
from bsn_edge.labels.config import LabelConfig

PROG = "bsn-adapt"


def build_parser() -> argparse.ArgumentParser:
    d = AdaptConfig()
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Adapt a trained run to your dashcam and roads from a few minutes of your own driving, with no "
                    "labels and no outside model. Each clip is labelled with T-frame blind spots made from the run's "
                    "own depth head (aligned to the built-in visual odometry's landmarks, clips that do not fit are "
                    "rejected), the run's segmentation teacher and the built-in visual odometry; B is fine-tuned on "
                    "them (D stays as trained), the threshold is chosen on held-out clips by agreement with their "
                    "labels, and the adapted run is written to --out (with --export, its int8 model too). Only "
                    "frames and the camera file are read: a sequence folder's depth, segmentation, poses and true "
                    "blind spots are not. The report (clips used and rejected with the reason, label coverage, "
                    "agreement before and after) goes to OUT/adapt/report.json.")
    p.add_argument("--run", required=True, help="the trained run to adapt (bsn-train --out)")
    p.add_argument("--video", nargs="+", required=True, metavar="CLIP",
                   help="your recordings: video files, folders of frame images (with --fps) or sequence folders")
    p.add_argument("--out", required=True, help="the adapted run's folder")
    p.add_argument("--calib", default=None, metavar="CALIB.json",
                   help="your camera file from bsn-calibrate (intrinsics, lens, mounting); without it a sequence "
                        "folder's own camera file is used, else the model camera's field of view is assumed")
    p.add_argument("--teacher", default=None, metavar="RUN",
                   help="a run whose segmentation teacher labels road, pavement and road users instead of --run's "
                        "own (a run folder or its teacher/ folder; D's depth and the distillation stay --run's)")
    p.add_argument("--camera-height", type=float, default=None, metavar="M",
                   help="the camera's height above the road, metres: with no camera file, a clip the depth head "
                        f"does not fit is labelled from the road plane at this height (default {ASSUMED_HEIGHT_M:g}, "
                        "the model camera's; pitch and yaw come from the direction of travel)")
    p.add_argument("--fps", type=float, default=None, help="frame rate of folders of images (videos say their own)")
    p.add_argument("--steps", type=int, default=d.steps, help=f"fine-tuning steps (default {d.steps})")
    p.add_argument("--lr", type=float, default=d.lr, help=f"fine-tuning learning rate (default {d.lr:g})")
    p.add_argument("--T", dest="horizon", type=float, default=d.labels.horizon_s,
                   help=f"blind-spot horizon T, seconds (default {d.labels.horizon_s:g})")
    p.add_argument("--rate", type=float, default=d.labels.rate,
                   help=f"label rate, frames/s (default {d.labels.rate:g})")
    p.add_argument("--min-corr", type=float, default=d.labels.min_corr,
                   help="reject clips whose depth/landmark alignment correlation is below this "
                        f"(default {d.labels.min_corr:g}, as bsn-label)")
    p.add_argument("--label-depth", default=d.label_depth, choices=LABEL_DEPTHS,
                   help="depth the labels are made with: model (the run's depth head), ground (the road plane "
                        "of your camera's mounting, things at their ground contact; needs a camera file with a "
                        "mounting, from bsn-calibrate --mount), auto (the depth head, and the road plane for a clip "
                        f"it does not fit when the mounting is known; default {d.label_depth})")
    p.add_argument("--look-tol", type=float, default=d.labels.look_tol, metavar="GREY",
                   help="for clips labelled from the road plane: warped road that looks like the label frame "
                        "within this many grey levels (0-255) is visible, not a blind spot; 0 turns the check "
                        f"off (default {d.labels.look_tol:g}, see bsn-label)")
    p.add_argument("--holdout", type=float, default=d.holdout_fraction,
                   help="share of the labelled frames held out to choose the threshold "
                        f"(default {d.holdout_fraction:g})")
    p.add_argument("--seed", type=int, default=d.seed, help="data order and augmentation seed (default 0)")
    p.add_argument("--export", action="store_true", help="also write OUT/model_int8.onnx (quantized on your frames)")
    p.add_argument("--sign", metavar="KEY.pem",
                   help="with --export: sign the model with this Ed25519 private key (without one it is unsigned, "
                        "and bsn-run runs it only with --allow-unsigned)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted adaptation in --out: imported clips and finished labels are kept "
                        "(fine-tuning, a few minutes, runs again)")
    p.add_argument("--force", action="store_true", help="start again in an --out that already holds a run")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from bsn_edge.adapt.pipeline import AdaptError, adapt  # torch: after the command line, which needs none

    if args.sign:
        if not args.export:
            return fail(PROG, "--sign signs the exported model: it needs --export")
        from bsn_edge.export.signing import load_private_key
        try:
            load_private_key(args.sign)      # a bad key is refused before any work
        except (FileNotFoundError, ValueError) as e:
            return fail(PROG, str(e))
    try:
        labels = LabelConfig(rate=args.rate, horizon_s=args.horizon, min_corr=args.min_corr, look_tol=args.look_tol,
                             camera_height=args.camera_height)
        cfg = AdaptConfig(labels=labels, label_depth=args.label_depth, holdout_fraction=args.holdout,
                          steps=args.steps, lr=args.lr, seed=args.seed)
        rep = adapt(args.run, args.video, args.out, cfg, calib=args.calib, fps=args.fps, export=args.export,
                    resume=args.resume, force=args.force, progress=not args.quiet, teacher=args.teacher)
    except (AdaptError, FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    for name, c in rep["clips"].items():
        print(f"{name}: {c['label_frames']} label frames, blind spots {100 * c['blind_spot_share_of_v']:.1f} % of V, "
              f"depth ({c.get('label_depth', 'model')})/landmark correlation {c['depth']}, camera: {c['camera']}")
    for name, why in rep["rejected"].items():
        print(f"{name}: rejected: {why}")
    a = rep["agreement"]
    print(f"agreement with held-out labels (IoU inside V): before {a['before']['iou']:.3f} at "
          f"{a['before']['threshold']:.2f}, after {a['after']['iou']:.3f} at {a['after']['threshold']:.2f}")
    if "kept_source" in rep:
        print(f"kept the source model: {rep['kept_source']}")
    if "export" in rep:
        print(f"wrote {rep['export']['path']}" + (f": {rep['export']['note']}" if rep["export"].get("shipped") else ""))
        from bsn_edge.cli.export import signed
        if signed(Path(rep["export"]["path"]), args.sign):
            return 2
    print(f"wrote the adapted run to {args.out} (report: {args.out}/adapt/report.json)")
    print(json.dumps({"weights_sha256": rep["weights_sha256"][:16], "seconds": rep["seconds"]}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
