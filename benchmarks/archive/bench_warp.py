"""The warp into the model camera, stage by stage, on the real clips with their cameras.

    python -m benchmarks.archive.bench_warp [--frames 300] [--rounds 5] [--out benchmarks/results]

For each clip (the 1280x720 Udacity clip with its camera file; the same clip and the 960x540
highway clip as ``bsn-run`` takes them without one: the model camera, rescaled), OpenCV on one
thread, as ``bsn-run``'s feeder runs it: the area shrink, the low-pass, and the remap two ways on
the same picture and the same fixed-point maps: with every tap mirrored into the picture beforehand
(``ModelFrame``'s maps) and with OpenCV testing and mirroring each tap (``BORDER_REFLECT``), which
costs where the raw camera sees only part of the model frame. The two remaps alternate, ``--rounds``
times; each stage's figure is the median over the rounds of its median milliseconds per frame. Their
pictures must agree within one grey level.
"""

from __future__ import annotations

import argparse
import statistics
from collections.abc import Callable

import cv2
import numpy as np

from bsn_edge.calibration import Calibration
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.model_frame import ModelFrame, block_mean
from bsn_edge.runtime import Engine
from bsn_edge.sequence.media import read_video

from ..bench_realcam import REAL, udacity_camera
from ..common import time_calls, write_result


def ms_per_call(fn: Callable[[int], object], n: int) -> float:
    """Median milliseconds of a call of ``fn(i)``, ``i`` from 0 to ``n`` - 1, after 5 warm-up calls."""
    return 1e3 * statistics.median(time_calls(fn, n, warmup=5))


def stages(mf: ModelFrame, frames: list[np.ndarray], n: int, rounds: int) -> dict[str, float]:
    """Median milliseconds per frame of each stage of ``mf``'s warp, the two remaps alternating."""
    pictures = [mf.low_passed(f) for f in frames]
    k = mf.shrink
    out = np.empty((mf.model.height, mf.model.width, 3), np.uint8)
    sx, sy = mf.picture_maps()
    opencv_maps = cv2.convertMaps(sx.astype(np.float32), sy.astype(np.float32), cv2.CV_16SC2)
    m = len(frames)

    def mirrored(i: int) -> None:
        cv2.remap(pictures[i % m], *mf.fixed_maps, cv2.INTER_LINEAR, dst=out, borderMode=cv2.BORDER_REPLICATE)

    def opencv(i: int) -> None:
        cv2.remap(pictures[i % m], *opencv_maps, cv2.INTER_LINEAR, dst=out, borderMode=cv2.BORDER_REFLECT)

    a = cv2.remap(pictures[0], *mf.fixed_maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    b = cv2.remap(pictures[0], *opencv_maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    diff = int(np.abs(a.astype(int) - b).max())
    small = [block_mean(f, k) for f in frames] if k > 1 else frames
    runs: dict[str, list[float]] = {"shrink": [], "low_pass": [], "remap_mirrored": [], "remap_opencv": [],
                                    "to_model": []}
    for _ in range(rounds):
        if k > 1:
            runs["shrink"].append(ms_per_call(lambda i: block_mean(frames[i % m], k), n))
        if mf.prefilter:
            runs["low_pass"].append(ms_per_call(lambda i: cv2.GaussianBlur(small[i % m], (3, 3), 0), n))
        runs["remap_mirrored"].append(ms_per_call(mirrored, n))
        runs["remap_opencv"].append(ms_per_call(opencv, n))
        runs["to_model"].append(ms_per_call(lambda i: mf.to_model(frames[i % m], dst=out), n))
    res = {key: statistics.median(v) if v else 0.0 for key, v in runs.items()}
    return {**res, "unseen": float(1 - mf.seen.mean()), "shrink_k": k, "low_pass_on": mf.prefilter,
            "max_difference": diff}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=300, help="calls per stage and round")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--model", default=str(DEFAULT_MODEL), help="the model whose camera frames are warped into")
    p.add_argument("--out", default="benchmarks/results")
    args = p.parse_args(argv)
    if not REAL.is_dir():
        print(f"no real data at {REAL}: nothing to measure")
        return 0
    cv2.setNumThreads(1)
    card = Engine(args.model, threads=1).card
    udacity = read_video(REAL / "udacity_test_video.mp4", 30)
    highway = read_video(REAL / "dashcam_highway.mp4", 30)
    cases: list[tuple[str, list[np.ndarray], Calibration | None]] = [
        ("udacity 1280x720, camera file", udacity, udacity_camera()[1]),
        ("udacity 1280x720, model camera assumed", udacity, None),
        ("highway 960x540, model camera assumed", highway, None)]
    result, rows = {}, []
    for name, frames, cal in cases:
        h, w = frames[0].shape[:2]
        cam = cal or Calibration.of(card.camera.scaled(w, h), (), None)
        mf = cam.model_frame(w, h, card.camera, card.mounting, mounting=cam.mounting or card.mounting)
        r = stages(mf, frames, args.frames, args.rounds)
        result[name] = r
        print(name, {k: round(v, 3) if isinstance(v, float) else v for k, v in r.items()})
        gain = r["remap_opencv"] - r["remap_mirrored"]
        rows.append(f"| {name} | {100 * r['unseen']:.0f} % | {r['shrink']:.2f} (x{r['shrink_k']}) | "
                    f"{r['low_pass']:.2f} | {r['remap_mirrored']:.2f} | {r['remap_opencv']:.2f} | {gain:+.2f} | "
                    f"{r['to_model']:.2f} | {r['max_difference']} |")
    md = "\n".join([
        "# The warp into the model camera, stage by stage", "",
        f"OpenCV on one thread, {args.frames} frames per stage and round, median of {args.rounds} rounds "
        "(milliseconds per frame). Remap: the same picture and fixed-point maps, with every tap mirrored into the "
        "picture beforehand (what `bsn-run` runs) or mirrored by OpenCV tap by tap (`BORDER_REFLECT`, the earlier "
        "warp), alternating. Unseen: the share of the model frame the raw camera does not see.", "",
        "| clip, camera | unseen | area shrink ms | low-pass ms | remap, mirrored maps ms | remap, OpenCV "
        "mirroring ms | saved ms | whole warp ms | largest difference (grey levels) |",
        "|---|---|---|---|---|---|---|---|---|", *rows])
    write_result(args.out, "warp", result, md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
