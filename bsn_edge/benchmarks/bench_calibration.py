"""Online calibration: frames to convergence, the estimate, and the estimator's share of a core.

    python -m bsn_edge.benchmarks.bench_calibration [--model MODEL.onnx] \\
        --clip ../shared/data/real/udacity_test_video.mp4 --clip ../shared/data/real/dashcam_highway.mp4 \\
        --clip ../shared/data/real/mountain_highway.mp4 --synthetic 5 --out benchmarks/results

Each clip is fed frame by frame to the runtime's camera state (``CameraState``, no camera file:
online calibration, as ``bsn-run`` does without ``--calib``), once per setting of the estimator
(:data:`SETTINGS`): the tracking estimator of ``bsn-calibrate --mount`` on every frame, the runtime's
online estimator at its share, and the same with the essential matrix fitted by plain RANSAC (the
estimator before USAC_ACCURATE refined each pair's direction of travel). Which
frames reach the estimator and the frame at which the mounting is adopted depend on the frame
count only (``OnlineCalibrator``), so those are exact counts. The estimator's CPU time (the thread's
own, on the caller's thread) until it converged, per second of video, is a timing: its share of one
core; take it on a quiet CPU. Synthetic clips (``--synthetic N``: N varied cameras, 20 s at 25
frames/s) carry their true mounting, and the intrinsics are given from their camera file (the
mounting is what is estimated).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2

from bsn_edge.calibration import Calibration
from bsn_edge.calibration.mount_fit import MountFitConfig
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.runtime.calibrator import ONLINE_FIT
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.synth import SynthConfig, write_clip

from .runner import Report, run

SYNTH_FRAMES = 500
SYNTH_FPS = 25.0                # a dashcam's rate: the runtime then feeds one frame in 2
SYNTH_SEEDS = (971, 972, 973, 974, 975)
# (short name, name, estimator, frames a second fed to it: None = every frame)
SETTINGS: tuple[tuple[str, str, MountFitConfig, float | None], ...] = (
    ("every", "tracking, every frame", MountFitConfig(), None),
    ("online", f"online, {CameraState.CALIBRATE_HZ:g}/s (runtime)", ONLINE_FIT, CameraState.CALIBRATE_HZ),
    ("ransac", f"online, {CameraState.CALIBRATE_HZ:g}/s, RANSAC (before)", replace(ONLINE_FIT, essential="ransac"),
     CameraState.CALIBRATE_HZ),
)


def converge(card, video: Path, estimator: MountFitConfig, hz: float | None,
             calibration: Calibration | None) -> dict[str, Any]:
    """Feed ``video`` to a calibrating camera state; when (frame index) and what it adopted, and the
    estimator's CPU seconds while calibrating."""
    if calibration is not None:       # intrinsics known, mounting to be found
        calibration = Calibration.of(calibration.intrinsics, calibration.dist, None)
    cam = CameraState(card, calibration, calibrate_every=1 if hz is None else None, background=False,
                      estimator=estimator, calibrate_hz=hz)
    cap = cv2.VideoCapture(str(video))
    fps = cap.get(cv2.CAP_PROP_FPS) or 10.0
    cam.use_frame_rate(fps)
    n, adopted, cpu_s = 0, None, 0.0
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)      # the estimator's work all on this thread, where thread_time counts it
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        calibrating = cam.calibrating
        t0 = time.thread_time()
        cam.observe(frame)
        cam.frame_for(frame)
        if calibrating:
            cpu_s += time.thread_time() - t0
        n += 1
        if adopted is None and not cam.calibrating:
            adopted = n
    cv2.setNumThreads(threads)
    cap.release()
    cam.close()
    r = cam.report
    calibrating_s = (adopted or n) / fps
    out: dict[str, Any] = {"every": cam.calibrate_every, "frames": n, "fps": fps, "converged_at_frame": adopted,
                           "estimator_cpu_share": round(cpu_s / calibrating_s, 3),
                           "converged_at_s": None if adopted is None else round(adopted / fps, 2),
                           "pairs": r.get("pairs"), "used": r.get("used"),
                           "standard_error_deg": r.get("standard_error_deg")}
    m = cam.mounting
    if m is not None:
        out.update(pitch_deg=round(m.pitch_deg, 3), yaw_deg=round(m.yaw_deg, 3), roll_deg=round(m.roll_deg, 3))
    return out


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default=str(DEFAULT_MODEL),
                   help="whose card gives the model camera (default: the shipped one)")
    p.add_argument("--clip", action="append", default=[], help="a video (real: no truth)")
    p.add_argument("--synthetic", type=int, default=len(SYNTH_SEEDS),
                   help="synthetic clips with known mountings (0: none)")
    p.add_argument("--cache", help="keep the synthetic clips in this folder and reuse them (default: rendered "
                                   "into a temporary folder each run)")
    p.add_argument("--setting", choices=[short for short, _, _, _ in SETTINGS],
                   action="append", help="only these settings of the estimator (default: all; 'every' is the "
                                         "tracking estimator on every frame, 'ransac' the online one with the "
                                         "essential matrix's earlier fit)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="calibration", help="the report's name in --out")
    return p


def _clips(args: argparse.Namespace, tmp: str) -> list[tuple[str, Path, Calibration | None]]:
    """The videos asked for (no truth) and the synthetic drives with their true mountings."""
    clips: list[tuple[str, Path, Calibration | None]] = [(Path(c).name, Path(c), None) for c in args.clip]
    for seed in SYNTH_SEEDS[:args.synthetic]:
        seq = Path(args.cache or tmp) / f"synthetic_{seed}"
        if not (seq / SequenceFolder.CALIBRATION).is_file() or not (seq / SequenceFolder.VIDEO).is_file():
            # an incomplete clip in the cache (an interrupted run) is rendered again
            write_clip(SynthConfig(frames=SYNTH_FRAMES, fps=SYNTH_FPS, seed=seed, style="suburb"), seq, force=True)
        clips.append((seq.name, seq / SequenceFolder.VIDEO, Calibration.read(seq / SequenceFolder.CALIBRATION)))
    return clips


def _against_truth(res: dict[str, Any], truth: Calibration | None) -> None:
    """The true mounting and the estimate's error beside it, when the clip has one."""
    if truth is None or truth.mounting is None:
        return
    t = truth.mounting
    res["truth"] = {"pitch_deg": round(t.pitch_deg, 3), "yaw_deg": round(t.yaw_deg, 3),
                    "roll_deg": round(t.roll_deg, 3)}
    if "pitch_deg" in res:
        res["error_deg"] = {"pitch": round(res["pitch_deg"] - t.pitch_deg, 3),
                            "yaw": round(res["yaw_deg"] - t.yaw_deg, 3)}


def _tables(rows: list[dict[str, Any]], chosen: tuple) -> list[str]:
    lines = ["| clip | estimator | frames to it | converged at | pitch / yaw (deg) | error vs truth (deg) "
             "| CPU share of one core |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        share = "every frame" if r["every"] == 1 else f"1 in {r['every']}"
        when = (f"frame {r['converged_at_frame']} ({r['converged_at_s']} s)" if r["converged_at_frame"]
                else f"not in {r['frames']} frames ({r['frames'] / r['fps']:.1f} s)")
        est = f"{r['pitch_deg']:+.2f} / {r['yaw_deg']:+.2f}" if "pitch_deg" in r else "-"
        err = (f"{r['error_deg']['pitch']:+.2f} / {r['error_deg']['yaw']:+.2f}" if "error_deg" in r else "-")
        lines.append(f"| {r['clip']} | {r['setting']} | {share} | {when} | {est} | {err} "
                     f"| {100 * r['estimator_cpu_share']:.0f} % |")
    lines += ["", "| estimator | synthetic clips converged in 20 s | median frames to convergence | "
              "median abs error pitch / yaw (deg) | median CPU share |", "|---|---|---|---|---|"]
    for setting, _, _ in chosen:
        syn = [r for r in rows if r["setting"] == setting and "truth" in r]
        done = [r for r in syn if r["converged_at_frame"]]
        errs = [r["error_deg"] for r in done]
        frames = _median([r["converged_at_frame"] for r in done])
        pitch, yaw = _median([abs(e["pitch"]) for e in errs]), _median([abs(e["yaw"]) for e in errs])
        cpu = _median([r["estimator_cpu_share"] for r in syn])
        lines.append(f"| {setting} | {len(done)} of {len(syn)} | {frames:.0f} | {pitch:.2f} / {yaw:.2f} "
                     f"| {100 * cpu:.0f} % |")
    return lines


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    chosen = tuple(s[1:] for s in SETTINGS if not args.setting or s[0] in args.setting)
    card = Engine(args.model).card
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, video, truth in _clips(args, tmp):
            for setting, estimator, hz in chosen:
                res = converge(card, video, estimator, hz, truth)
                res.update(clip=name, setting=setting)
                _against_truth(res, truth)
                rows.append(res)
                print(res)
    md = ["# Online calibration: frames to convergence, and the estimator's cost", "", *_tables(rows, chosen)]
    return Report({"rows": rows}, md)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
