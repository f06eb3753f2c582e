"""``bsn-label``: T-frame blind-spot labels for sequence folders."""

from __future__ import annotations

import argparse
import os

from bsn_edge.cli.common import fail
from bsn_edge.labels import LabelConfig, Sources
from bsn_edge.labels.batch import label_many, label_many_ray
from bsn_edge.progress import progress_bar

PROG = "bsn-label"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Make T-frame blind-spot labels: road hidden in frame t that becomes visible "
                    "within the next T seconds, computed by forward-warping the traversable pixels of "
                    "later frames (BlindSpotNet, Section 3). Writes labels/T<T>s/{blindspot,visibility}/ "
                    "and report.json in each sequence folder; a rerun skips finished frames.")
    p.add_argument("seqs", nargs="+", metavar="SEQ", help="sequence folders")
    p.add_argument("--rate", type=float, default=5.0, help="label rate, frames/s (default 5)")
    p.add_argument("--T", dest="horizon", type=float, default=5.0, help="horizon T in seconds (default 5)")
    p.add_argument("--depth", default="files",
                   help="depth source: files | onnx:MODEL (a depth network) | bsn:MODEL (a bsn-edge model's depth, the "
                        "frame warped into its camera with the clip's calibration) | rel:DIR[:inverse] | ground "
                        "(the road plane of the camera file's mounting, things at their ground contact; reads "
                        "--seg) (default files)")
    p.add_argument("--seg", default="files", help="segmentation source: files | onnx:MODEL (default files)")
    p.add_argument("--poses", default="files",
                   help="poses: files (poses.txt) | vo (built-in visual odometry) | TRAJ.txt (KITTI or "
                        "TUM trajectory file) (default files)")
    p.add_argument("--depth-tol", type=float, default=1.0,
                   help="l_d, metres: warped road whose depth agrees with frame t's within this is "
                        "visible (default 1.0)")
    p.add_argument("--look-tol", type=float, default=0.0, metavar="GREY",
                   help="grey levels (0-255): warped road that also looks like frame t where it lands is "
                        "visible; for --depth ground with a segmentation model, whose outlines are a few "
                        "pixels off (bsn-adapt uses 8 there; default 0 = off)")
    p.add_argument("--vis-range", type=float, default=16.0,
                   help="L, metres: V is sky or a surface nearer than this (default 16)")
    p.add_argument("--users-unknown", action="store_true",
                   help="leave road users with no road seen behind them out of V (unknown, not taught as hiding "
                        "nothing): for drives whose frames are far apart, such as CamVid's a second apart")
    p.add_argument("--min-area", type=int, default=None,
                   help="drop label components smaller than this (pixels); default scales the paper's "
                        "100 px at 375x1242 with the image area")
    p.add_argument("--min-corr", type=float, default=0.7,
                   help="reject clips whose depth/landmark alignment correlation is below this (default 0.7)")
    p.add_argument("--calib", default="", metavar="CALIB.json",
                   help="camera file from bsn-calibrate (default: the clip's own calibration.json, if any): its "
                        "intrinsics, rescaled to the clip, replace meta.json's; with lens distortion, depth and "
                        "segmentation are undistorted first and the labels are made in the undistorted camera")
    p.add_argument("--camera-height", type=float, default=None,
                   help="camera height above the road, metres, for monocular VO's scale (default: "
                        "meta.json's camera_height, else 1.5)")
    p.add_argument("--force", action="store_true",
                   help="relabel clips whose labels for this T were made with other parameters or sources "
                        "(without it such clips are refused; a rerun with the same ones resumes)")
    p.add_argument("--jobs", type=int, default=None,
                   help="clips labelled in parallel (default: one per core, at most one per clip)")
    p.add_argument("--ray", metavar="ADDRESS", default=None,
                   help="run each clip as a Ray task on this cluster ('local' starts one here)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        cfg = LabelConfig(rate=args.rate, horizon_s=args.horizon, depth_tol=args.depth_tol,
                          vis_range=args.vis_range, min_area=args.min_area, min_corr=args.min_corr,
                          camera_height=args.camera_height, look_tol=args.look_tol,
                          users_unknown=args.users_unknown)
    except ValueError as e:
        return fail(PROG, str(e))
    sources = Sources(depth=args.depth, seg=args.seg, poses=args.poses, calib=args.calib)
    jobs = args.jobs or min(len(args.seqs), os.cpu_count() or 1)
    if jobs < 1:
        return fail(PROG, f"--jobs must be >= 1, got {jobs}")
    with progress_bar(total=0, desc="label", unit="frame") as bar:
        def on_total(n: int) -> None:
            bar.total = (bar.total or 0) + n
            bar.refresh()
        if args.ray:
            try:
                results = label_many_ray(args.seqs, cfg, sources, args.ray, progress=bar.update, force=args.force)
            except RuntimeError as e:
                return fail(PROG, str(e))
        else:
            results = label_many(args.seqs, cfg, sources, jobs, progress=bar.update, on_total=on_total,
                                 force=args.force)
    width = max(len(r.seq) for r in results)
    for r in results:
        line = f"{r.seq:<{width}}  {r.status:<8}"
        if r.status == "ok":
            line += f"  {r.label_frames} frames ({r.resumed_frames} already done) in {r.seconds:.1f} s"
        else:
            line += f"  {r.message}"
        print(line)
    bad = [r for r in results if r.status != "ok"]
    if bad:
        print(f"{PROG}: {len(bad)} of {len(results)} clips not labelled (see above)")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
