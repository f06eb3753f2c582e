"""The first guess of a camera nobody calibrated: pitch and yaw from the road's vanishing point.

    python -m bsn_edge.benchmarks.bench_vanishing --out benchmarks/results

Per picture, :func:`~bsn_edge.calibration.vanishing_point.find_vanishing_point` and the mounting it
gives, against a mounting known another way:

- rendered clips of varied cameras (two per style, seeds no training clip has; three frames each),
  with their rig's true mounting; the intrinsics and lens from their camera file, as a user with a
  camera file but no mounting has them;
- DDAD's front camera: its extrinsics and the LiDAR road plane under the car;
- the Udacity clip: its camera file (chessboard, then ``bsn-calibrate --mount``), every frame;
- the highway dashcam (no camera file): where ``bsn-run``'s online calibration converges, with the
  intrinsics it assumes.

And what ``bsn-run`` uses while calibrating (:class:`~bsn_edge.calibration.vanishing_point.
VanishingGuess`, the median over the first frames where the point is found) on the real clips. No
timing is taken. Real data beside the checkout (``../shared/data/real``); without it only the
rendered part runs, and the report says so.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.calibration import Calibration
from bsn_edge.calibration.vanishing_point import find_vanishing_point
from bsn_edge.cli.common import REAL_DATA
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.mounting import Mounting
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.sequence.frames import read_rgb
from bsn_edge.sequence.media import read_video
from bsn_edge.synth import SynthConfig, write_clip

from . import runner
from .runner import Report

STYLES = ("town", "suburb", "highway", "urban")
SEEDS = (981, 982)               # per style, apart from every training and held-out seed
FRAMES = (0, 4, 8)


def _error(m, truth) -> tuple[float, float] | None:
    return None if m is None else (m.pitch_deg - truth.pitch_deg, m.yaw_deg - truth.yaw_deg)


def rendered(work: Path) -> list[dict[str, Any]]:
    rows = []
    for style in STYLES:
        for seed in SEEDS:
            clip = write_clip(SynthConfig(frames=max(FRAMES) + 1, style=style, seed=seed, lead=0.0),
                              work / f"{style}_{seed}", video=False)
            cal = Calibration.read(clip / "calibration.json")
            t = _known(cal.mounting, clip)
            for i in FRAMES:
                bgr = cv2.cvtColor(read_rgb(clip, i), cv2.COLOR_RGB2BGR)
                m = find_vanishing_point(bgr).mounting(cal.intrinsics, t.height_m, t.roll_deg, cal.dist)
                rows.append({"picture": f"{style} seed {seed} frame {i}", "error_deg": _error(m, t)})
    return rows


def real() -> list[dict[str, Any]]:
    from .real_samples import ddad_samples, udacity_camera

    rows = []
    for s in ddad_samples("front"):
        t = _known(s.camera.mounting, s.name)
        m = find_vanishing_point(s.image).mounting(s.camera.intrinsics, t.height_m, t.roll_deg, s.camera.dist)
        rows.append({"picture": s.name, "truth": "extrinsics and LiDAR road plane", "error_deg": _error(m, t)})
    cal = udacity_camera()[1]
    truth = _known(cal.mounting, "the Udacity camera file")
    frames = read_video(REAL_DATA / "udacity_test_video.mp4")
    for i, f in enumerate(frames):
        m = find_vanishing_point(f).mounting(cal.intrinsics, 1.5, truth.roll_deg, cal.dist)
        rows.append({"picture": f"udacity_test_video frame {i}", "truth": "camera file",
                     "error_deg": _error(m, truth)})
    return rows


def in_bsn_run(name: str, card) -> dict[str, Any]:
    """The guess ``bsn-run`` warps with while it calibrates, and where online calibration converges."""
    frames = read_video(REAL_DATA / name)
    camera = CameraState(card, background=False)
    camera.use_frame_rate(cv2.VideoCapture(str(REAL_DATA / name)).get(cv2.CAP_PROP_FPS) or 25.0)
    guess = None
    for f in frames:
        camera.observe(f)
        if camera.calibrating:
            guess = camera.summary()["first_guess"]
    camera.close()
    return {"clip": name, "first_guess": guess,
            "online": None if camera.mounting is None else camera.mounting.to_dict()}


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    errs = [r["error_deg"] for r in rows if r["error_deg"] is not None]
    a = np.abs(np.array(errs)) if errs else np.zeros((0, 2))
    stat = (lambda f: [round(float(f(a[:, k])), 2) for k in (0, 1)]) if len(a) else (lambda f: None)
    return {"pictures": len(rows), "found": len(errs), "median_abs_deg": stat(np.median),
            "p90_abs_deg": stat(lambda x: np.percentile(x, 90)),
            "within_1_deg": int((a < 1.0).all(axis=1).sum()) if len(a) else 0}


def _known(mounting: Mounting | None, where: object) -> Mounting:
    """The mounting a reading is judged against; ``RuntimeError`` naming ``where`` when it has none."""
    if mounting is None:
        raise RuntimeError(f"{where}: no mounting to judge the vanishing point against")
    return mounting


def _line(name: str, s: dict[str, Any]) -> str:
    med, p90 = s["median_abs_deg"], s["p90_abs_deg"]
    return (f"| {name} | {s['found']} of {s['pictures']} | " + (f"{med[0]} / {med[1]} | {p90[0]} / {p90[1]} | "
            f"{s['within_1_deg']}" if med else "- | - | 0") + " |")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="vanishing", help="the report's name in --out")
    return p


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    with tempfile.TemporaryDirectory() as tmp:
        synth = rendered(Path(tmp))
    have_real = (REAL_DATA / "udacity_test_video.mp4").is_file() and (REAL_DATA / "ddad_dgp").is_dir()
    reals = real() if have_real else []
    ddad = [r for r in reals if r["picture"].startswith("ddad")]
    udacity = [r for r in reals if r["picture"].startswith("udacity")]
    card = Engine(str(DEFAULT_MODEL)).card
    runs = [in_bsn_run(n, card) for n in ("dashcam_highway.mp4", "mountain_highway.mp4", "udacity_test_video.mp4")
            if (REAL_DATA / n).is_file()]
    result: dict[str, Any] = {"rendered": {"rows": synth, **summarise(synth)},
                              "ddad_front": {"rows": ddad, **summarise(ddad)},
                              "udacity": {"rows": udacity, **summarise(udacity)}, "bsn_run": runs}
    md = ["# The first guess: pitch and yaw from the road's vanishing point", "",
          "Per picture, the vanishing point of the road's lines and the pitch and yaw it gives "
          "(`bsn_edge/calibration/vanishing_point.py`), against a mounting known another way. Errors in "
          "degrees, pitch / yaw; found: pictures where lines leaning both ways agreed on a point.", "",
          "| set | found | median abs. error | 90th percentile | within 1 degree (both) |",
          "|---|---|---|---|---|",
          _line(f"rendered, varied cameras ({len(STYLES)} styles x {len(SEEDS)} seeds x {len(FRAMES)} frames; "
                "the rig's mounting)", result["rendered"])]
    if have_real:
        md += [_line("DDAD front camera (extrinsics, LiDAR road plane)", result["ddad_front"]),
               _line("Udacity clip, every frame (its camera file)", result["udacity"])]
    else:
        md.append("\nReal data absent (`../shared/data/real`): the real rows are left out.")
    if runs:
        md += ["", "What `bsn-run` warps with while it calibrates (the median over the first frames where the "
               "point is found, with the intrinsics it assumes without a camera file), and where online "
               "calibration converges:", "",
               "| clip | first guess pitch / yaw | frames found / looked | online calibration pitch / yaw |",
               "|---|---|---|---|"]
        for r in runs:
            g, o = r["first_guess"], r["online"]
            md.append(f"| {r['clip']} | " + (f"{g['pitch_deg']:+.2f} / {g['yaw_deg']:+.2f} | {g['frames_found']} / "
                                              f"{g['frames_looked']}" if g and g["pitch_deg"] is not None
                                              else "none found | -")
                      + " | " + (f"{o['pitch_deg']:+.2f} / {o['yaw_deg']:+.2f}" if o else "not converged") + " |")
    return Report(result, md, md)


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
