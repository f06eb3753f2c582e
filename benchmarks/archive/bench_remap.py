"""bsn-run end to end with the model camera's remap, against a reference build that resized.

    python -m benchmarks.archive.bench_remap --out benchmarks/results --ref-python OLD/bin/python
    python -m benchmarks.archive.bench_remap --ref-python OLD/bin/python --ref-camera --name remap_mirror

``--ref-camera``: the reference is a build with the model camera too (a change to the warp), so it
reads the same camera files and calibrates online the same way; ``--name`` names the report.
``--overlay``: every run also writes the overlay video (``bsn-run --overlay``).

``--ref-python`` is an interpreter whose ``bsn_edge`` is the reference (e.g. the release before
the model camera, installed in its own environment). Both run the same model on the same real
clips (``../shared/data/real``: the 1280x720 Udacity clip looped to 190 frames, with its camera
file; the 960x540 highway clip, model camera assumed), alternating, ``--repeats`` times each; the
median frame rate of each is compared. The current build runs with a camera file that carries a
mounting (the steady state: no online calibration), and, separately, while calibrating online.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2

from bsn_edge.calibration import Calibration, calibrate
from bsn_edge.camera import Intrinsics
from bsn_edge.cli.common import REAL_DATA
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.mounting import Mounting
from bsn_edge.sequence.media import read_video

from ..common import write_result

REAL, MODEL = REAL_DATA, DEFAULT_MODEL
GOAL = 0.95


def loop_video(src: Path, out: Path, times: int) -> Path:
    frames = read_video(src)
    h, w = frames[0].shape[:2]
    vw = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), 25, (w, h))
    for _ in range(times):
        for f in frames:
            vw.write(f)
    vw.release()
    return out


def fps(python: str, model: Path, source: Path, work: Path, extra: list[str], overlay: bool = False) -> float:
    summary = work / "s.json"
    cmd = [python, "-m", "bsn_edge.cli.run", "--model", str(model), "--source", str(source), "--summary",
           str(summary), *extra, *(("--overlay", str(work / "overlay.mp4"), "--force") if overlay else ())]
    subprocess.run(cmd, check=True, capture_output=True, cwd=work)
    return float(json.loads(summary.read_text())["fps"])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--ref-python", required=True, help="interpreter of the reference build")
    p.add_argument("--model", default=str(MODEL))
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--ref-camera", action="store_true",
                   help="the reference has the model camera too: it runs with the same camera files")
    p.add_argument("--name", default="remap", help="the report's name in --out")
    p.add_argument("--overlay", action="store_true", help="every run also writes the overlay video")
    args = p.parse_args(argv)
    if not REAL.is_dir():
        print(f"no real data at {REAL}: nothing to measure")
        return 0
    rows, result = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        uda = loop_video(REAL / "udacity_test_video.mp4", work / "udacity.mp4", 5)
        cam = calibrate(REAL / "camera_cal").with_mounting(Mounting(1.2, -1.8, 0.8), method="benchmark")
        cam_path = work / "camera.json"
        cam.write(cam_path)
        # the highway clip's intrinsics are unknown: the model camera's 80 degrees, rescaled
        hw = Calibration.of(Intrinsics.from_fov(960, 540, 80.0), (), Mounting(1.3, 0.0))
        hw_path = work / "highway.json"
        hw.write(hw_path)
        cases = {"udacity 1280x720": (uda, ["--calib", str(cam_path)]),
                 "highway 960x540": (REAL / "dashcam_highway.mp4", ["--calib", str(hw_path)])}
        for name, (src, extra) in cases.items():
            if args.ref_camera:
                runs = {"reference_fps": (args.ref_python, extra), "reference_calibrating_fps": (args.ref_python, []),
                        "model_camera_fps": (sys.executable, extra), "calibrating_fps": (sys.executable, [])}
            else:
                runs = {"reference_fps": (args.ref_python, []), "model_camera_fps": (sys.executable, extra),
                        "calibrating_fps": (sys.executable, [])}
            got: dict[str, list[float]] = {k: [] for k in runs}
            for _ in range(args.repeats):
                for k, (python, more) in runs.items():
                    got[k].append(fps(python, Path(args.model), src, work, more, args.overlay))
            med = {k: statistics.median(v) for k, v in got.items()}
            r, c, o = med["reference_fps"], med["model_camera_fps"], med["calibrating_fps"]
            result[name] = {**got, "ratio": c / r}
            if args.ref_camera:
                ro = med["reference_calibrating_fps"]
                result[name]["calibrating_ratio"] = o / ro
                rows.append(f"| {name} | {r:.1f} | {c:.1f} ({c / r:.0%}) | {ro:.1f} | {o:.1f} ({o / ro:.0%}) |")
            else:
                result[name]["calibrating_ratio"] = o / r
                rows.append(f"| {name} | {r:.1f} | {c:.1f} ({c / r:.0%}) | {o:.1f} ({o / r:.0%}) |")
    ok = all(v["ratio"] >= GOAL for v in result.values())
    if args.ref_camera:
        title = "# bsn-run end to end: this build's warp against a reference build's"
        head = ["| clip | reference, camera file | this build, camera file | reference, calibrating | "
                "this build, calibrating |", "|---|---|---|---|---|"]
        goal = f"Goal: this build within 5 % of the reference or faster: {'met' if ok else 'not met'}."
    else:
        title = "# bsn-run end to end: the model camera's remap against the resize"
        head = ["| clip | reference (resize) | model camera, camera file with mounting | calibrating online |",
                "|---|---|---|---|"]
        goal = f"Goal: the model camera within 5 % of the resize: {'met' if ok else 'not met'}."
    md = "\n".join([title, "",
                    f"Median of {args.repeats} alternating runs each, frames/s through `bsn-run` (decode, warp, model, "
                    f"sectors, senders{', the overlay video' if args.overlay else ''}), the shipped int8 model, "
                    "2 threads.", "",
                    *head, *rows, "", goal])
    write_result(args.out, args.name, result, md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
