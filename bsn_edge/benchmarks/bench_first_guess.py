"""What the first guess of an unknown camera wins or costs: each source scored three ways, side by side.

    python -m bsn_edge.benchmarks.bench_first_guess --out benchmarks/results [--model NAME=MODEL.onnx]

For a camera nobody calibrated, ``bsn-run`` warps with the road's vanishing point once the first
frames agree on it (:class:`~bsn_edge.calibration.vanishing_point.VanishingGuess`), else as the model
camera sits, while online calibration runs. Each source is scored

- **guess**: with no camera file, as ``bsn-run`` runs it (first guess, online calibration);
- **assumed**: with a camera file that says only what ``bsn-run`` assumes (the model camera's field of
  view and mounting): no guess, no calibration;
- **true**: with the source's own camera file, where it has one.

Sources: the ``realboxes`` frames that have a camera file (occluders marked, the rule of
``bench_realboxes``), CamVid's held-out drive (road users by pixel labels, ``bench_camvid``), and
rendered clips of varied cameras (two per style, seeds no training clip has; blind-spot IoU against the
renderer's true blind spots on the raw frames, after the first ``SETTLE`` frames). The guess ships only
where it is at least as good as the assumed camera on every source.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.calibration import Calibration
from bsn_edge.labels import camvid
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.sequence.frames import read_rgb
from bsn_edge.sequence.images import read_image
from bsn_edge.synth import SynthConfig, write_clip

from . import bench_camvid, bench_realboxes
from .bench_realboxes import frac
from .common import engines, models_parser
from .real_samples import REAL
from .runner import Report, run

MODES = ("guess", "assumed", "true")
STYLES = ("town", "suburb", "highway", "urban")
SEEDS = (981, 982)
FRAMES, SETTLE = 40, 10


def assumed_file(engine: Engine, width: int, height: int) -> Calibration:
    """A camera file of what ``bsn-run`` assumes: the model camera at the frame's size, sitting as it sits."""
    return Calibration.of(engine.card.camera.scaled(width, height), (), engine.card.mounting, method="assumed")


def realboxes(engine: Engine) -> dict[str, Any]:
    """The realboxes frames that have a camera file, their occluders marked three ways."""
    spec = json.loads(bench_realboxes.BOXES.read_text())
    frames = [f for f in bench_realboxes.load_frames(spec) if f.calibration is not None]
    rows: dict[str, list[dict[str, Any]]] = {m: [] for m in MODES}
    for fr in frames:
        h, w = fr.image.shape[:2]
        assumed = bench_realboxes.Frame(fr.name, fr.frames, assumed_file(engine, w, h), fr.boxes, fr.credit)
        for mode, frame, withheld in (("true", fr, False), ("guess", fr, True), ("assumed", assumed, False)):
            rows[mode] += bench_realboxes.score(bench_realboxes.blind_spots(engine, frame, withheld), fr.boxes)
    return {"frames": len(frames), **{m: bench_realboxes.summary(r) for m, r in rows.items()}}


def camvid_drive(engine: Engine) -> dict[str, Any]:
    """CamVid's held-out drive, its road users marked two ways (it has no camera file)."""
    frames = list(camvid.frames_of(REAL / "camvid", camvid.HELD_OUT, "train"))
    return {"frames": len(frames), "guess": bench_camvid.score_drive(engine, frames),
            "assumed": bench_camvid.score_drive(engine, frames, assumed=True)}


def rendered(engine: Engine, work: Path) -> dict[str, Any]:
    """Rendered clips of varied cameras: blind-spot IoU against the true blind spots, three ways."""
    counts = {m: np.zeros(2, np.int64) for m in MODES}      # intersection, union
    for style in STYLES:
        for seed in SEEDS:
            clip = write_clip(SynthConfig(frames=FRAMES, style=style, seed=seed), work / f"{style}_{seed}",
                              video=False)
            own = Calibration.read(clip / "calibration.json")
            frames = [cv2.cvtColor(read_rgb(clip, i), cv2.COLOR_RGB2BGR) for i in range(FRAMES)]
            truth = [read_image(clip / "bsgt" / f"{i:06d}.png", cv2.IMREAD_GRAYSCALE) > 0 for i in range(FRAMES)]
            h, w = frames[0].shape[:2]
            for mode, cal in (("guess", None), ("assumed", assumed_file(engine, w, h)), ("true", own)):
                state = CameraState(engine.card, cal, background=False)
                state.use_frame_rate(10.0)
                for i, f in enumerate(frames):
                    state.observe(f)
                    if i < SETTLE:
                        continue
                    mf = state.frame_for(f)
                    prob, _ = engine.infer(mf.to_model(f)[None])
                    mask = mf.to_raw(prob) >= engine.card.threshold
                    counts[mode] += (int((mask & truth[i]).sum()), int((mask | truth[i]).sum()))
                state.close()
    return {"clips": len(STYLES) * len(SEEDS), "frames_each": FRAMES - SETTLE,
            **{m: round(float(c[0] / max(c[1], 1)), 4) for m, c in counts.items()}}


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    models = engines(p, args.model)
    result: dict[str, Any] = {"models": {}}
    table = ["| model | source | guess (no camera file) | assumed camera file | true camera file |",
             "|---|---|---|---|---|"]
    for name, engine in models.items():
        r: dict[str, Any] = {}
        with tempfile.TemporaryDirectory() as tmp:
            r["rendered"] = rendered(engine, Path(tmp))
        g = r["rendered"]
        table.append(f"| {name} | rendered clips, blind-spot IoU ({g['clips']} clips, {g['frames_each']} frames "
                     f"each) | {g['guess']:.3f} | {g['assumed']:.3f} | {g['true']:.3f} |")
        if REAL.is_dir():
            rb = r["realboxes"] = realboxes(engine)
            table.append(f"| {name} | realboxes with a camera file ({rb['frames']} frames), near / all occluders "
                         "marked | " + " | ".join(f"{frac(rb[m]['near'])} / {frac(rb[m]['all'])}" for m in MODES)
                         + " |")
            cv = r["camvid"] = camvid_drive(engine)
            cells = [f"{frac(cv[m]['counts']['vehicles_near'])} / {frac(cv[m]['counts']['people_near'])} / "
                     f"{frac(cv[m]['counts']['road_users_all'])}" for m in ("guess", "assumed")]
            table.append(f"| {name} | CamVid {camvid.HELD_OUT} ({cv['frames']} frames), near cars / near people "
                         f"and cyclists / all road users | {cells[0]} | {cells[1]} | - |")
        result["models"][name] = r
    md = ["# The first guess of an unknown camera against the camera it assumes and the true one", "",
          "Each source scored with no camera file (as `bsn-run` runs it: the first guess, then online calibration), "
          "with a camera file of what `bsn-run` assumes (the model camera's field of view and mounting) and with "
          "its own camera file where it has one. Rendered clips: blind-spot IoU against the renderer's true blind "
          f"spots on the raw frames, frames {SETTLE}-{FRAMES - 1} of each. Real sources: the rules of "
          "[realboxes](realboxes.md) and [camvid](camvid.md).", "", *table]
    return Report(result, md, table)


def main(argv: list[str] | None = None) -> int:
    return run(measure, models_parser(__doc__, "first_guess"), argv)


if __name__ == "__main__":
    raise SystemExit(main())
