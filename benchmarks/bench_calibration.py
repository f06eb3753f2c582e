"""Online calibration: frames to convergence and the estimate, every frame vs the runtime's share.

    python -m benchmarks.bench_calibration --model models/bsn_small_light_int8.onnx \\
        --clip ../shared/data/real/udacity_test_video.mp4 --clip ../shared/data/real/dashcam_highway.mp4 \\
        --synthetic 3 --out benchmarks/results

Each clip is fed frame by frame to the runtime's camera state (``CameraState``, no camera file:
online calibration, as ``bsn-run`` does without ``--calib``), once with every frame going to the
estimator and once with the runtime's default share (about ``CameraState.CALIBRATE_HZ`` frames a
second). Which frames reach the estimator and the frame at which the mounting is adopted depend on
the frame count only (``OnlineCalibrator``), so these figures are exact counts, not timings.
Synthetic clips (``--synthetic N``: N varied cameras, 20 s at 25 frames/s) carry their true
mounting, and the intrinsics are given from their camera file (the mounting is what is estimated).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import cv2

from benchmarks.common import write_result
from bsn_edge.calibration import Calibration
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.synth import SynthConfig, write_clip

SYNTH_FRAMES = 500
SYNTH_FPS = 25.0                # a dashcam's rate: the runtime then feeds one frame in 3
SYNTH_SEEDS = (971, 972, 973, 974, 975)


def converge(card, video: Path, every: int | None, calibration: Calibration | None) -> dict[str, Any]:
    """Feed ``video`` to a calibrating camera state; when (frame index) and what it adopted."""
    if calibration is not None:       # intrinsics known, mounting to be found
        calibration = Calibration.of(calibration.intrinsics, calibration.dist, None)
    cam = CameraState(card, calibration, calibrate_every=every, background=False)
    cap = cv2.VideoCapture(str(video))
    cam.use_frame_rate(cap.get(cv2.CAP_PROP_FPS) or 10.0)
    fps = cap.get(cv2.CAP_PROP_FPS) or 10.0
    n, adopted = 0, None
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        cam.frame_for(frame)
        n += 1
        if adopted is None and not cam.calibrating:
            adopted = n
    cap.release()
    cam.close()
    r = cam.report
    out: dict[str, Any] = {"every": cam.calibrate_every, "frames": n, "fps": fps, "converged_at_frame": adopted,
                           "converged_at_s": None if adopted is None else round(adopted / fps, 2),
                           "pairs": r.get("pairs"), "used": r.get("used"),
                           "standard_error_deg": r.get("standard_error_deg")}
    m = cam.mounting
    if m is not None:
        out.update(pitch_deg=round(m.pitch_deg, 3), yaw_deg=round(m.yaw_deg, 3), roll_deg=round(m.roll_deg, 3))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default="models/bsn_small_light_int8.onnx", help="whose card gives the model camera")
    p.add_argument("--clip", action="append", default=[], help="a video (real: no truth)")
    p.add_argument("--synthetic", type=int, default=3, help="synthetic clips with known mountings (0: none)")
    p.add_argument("--out", default="benchmarks/results")
    args = p.parse_args(argv)
    card = Engine(args.model).card
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        clips: list[tuple[str, Path, Calibration | None]] = [(Path(c).name, Path(c), None) for c in args.clip]
        for seed in SYNTH_SEEDS[:args.synthetic]:
            seq = Path(tmp) / f"synthetic_{seed}"
            write_clip(SynthConfig(frames=SYNTH_FRAMES, fps=SYNTH_FPS, seed=seed, style="suburb"), seq)
            clips.append((seq.name, seq / SequenceFolder.VIDEO, Calibration.read(seq / SequenceFolder.CALIBRATION)))
        for name, video, truth in clips:
            for every in (1, None):
                res = converge(card, video, every, truth)
                res["clip"] = name
                if truth is not None and truth.mounting is not None:
                    t = truth.mounting
                    res["truth"] = {"pitch_deg": round(t.pitch_deg, 3), "yaw_deg": round(t.yaw_deg, 3),
                                    "roll_deg": round(t.roll_deg, 3)}
                    if "pitch_deg" in res:
                        res["error_deg"] = {"pitch": round(res["pitch_deg"] - t.pitch_deg, 3),
                                            "yaw": round(res["yaw_deg"] - t.yaw_deg, 3)}
                rows.append(res)
                print(res)
    lines = ["| clip | frames to the estimator | converged at | pitch / yaw (deg) | error vs truth (deg) |",
             "|---|---|---|---|---|"]
    for r in rows:
        share = "every frame" if r["every"] == 1 else f"1 in {r['every']}"
        when = (f"frame {r['converged_at_frame']} ({r['converged_at_s']} s)" if r["converged_at_frame"]
                else f"not in {r['frames']} frames ({r['frames'] / r['fps']:.1f} s)")
        est = f"{r['pitch_deg']:+.2f} / {r['yaw_deg']:+.2f}" if "pitch_deg" in r else "-"
        err = (f"{r['error_deg']['pitch']:+.2f} / {r['error_deg']['yaw']:+.2f}" if "error_deg" in r else "-")
        lines.append(f"| {r['clip']} | {share} | {when} | {est} | {err} |")
    md = "# Online calibration: frames to convergence\n\n" + "\n".join(lines)
    write_result(Path(args.out), "calibration", {"rows": rows}, md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
