"""Every real clip and image in ``../shared/data/real/``, seen by each model, side by side, for a person.

    python -m bsn_edge.benchmarks.bench_realview --out benchmarks/results [--model A.onnx --model B.onnx]

Each model sees a source the way ``bsn-run`` would (its ``CameraState``): DDAD with the camera
from its calibration and LiDAR road plane, the Udacity clip with the camera from the product's
own calibration steps, the 960x540 highway dashcam (intrinsics unknown) with no camera file
(online calibration over the whole clip), the city pair with its published intrinsics and the
model camera's mounting. Blind spots at the model's own threshold are tinted red on the raw frame;
one column per model. The pictures are derived from third-party data and are committed with the
source and licence line of the frames they show (``LICENCES``; the raw files themselves are never
redistributed). Nothing here is scored: the figures are
for judging by eye (light and dark cars, parked cars along curbs, nothing on sky, trees or open
road).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.calibration import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.sequence.images import read_image
from bsn_edge.sequence.media import read_video
from bsn_edge.synth.sheet import tint

from . import runner
from .common import load_engine, named
from .real_samples import REAL, ddad_samples, licence, udacity_samples
from .runner import Report

WIDTH = 480                # each panel's width in the figures
HIGHWAY_FRAMES = (60, 140, 220)


class Source:
    """Frames of one real source; ``shown`` are the indices drawn; ``calibration`` None: no camera file."""

    def __init__(self, name: str, frames: list[np.ndarray], shown: list[int], calibration: Calibration | None,
                 what: str) -> None:
        self.name, self.frames, self.shown, self.calibration, self.what = name, frames, shown, calibration, what


def sources() -> list[Source]:
    out = []
    ddad = ddad_samples()
    picks = [s for s in ddad if s.name.endswith("camviz")] + [s for s in ddad if "scene" in s.name][::3]
    for s in picks:
        out.append(Source(s.name, [s.image], [0], s.camera, "calibration extrinsics, LiDAR road plane"))
    uda, _ = udacity_samples()
    out.append(Source("udacity", [s.image for s in uda], [0, len(uda) // 2, len(uda) - 1], uda[0].camera,
                      "bsn-calibrate chessboard + --mount"))
    video = REAL / "dashcam_highway.mp4"
    if video.is_file():
        frames = read_video(video)
        out.append(Source("dashcam_highway", frames, [i for i in HIGHWAY_FRAMES if i < len(frames)], None,
                          "no camera file: online calibration"))
    pair = REAL / "manydepth_pair"
    if (pair / "target.jpg").is_file():
        imgs = [read_image(pair / n) for n in ("source.jpg", "target.jpg")]
        out.append(Source("city pair", imgs, [0, 1], city_pair_camera(imgs[0].shape[:2]),
                          "published intrinsics, model camera's mounting"))
    return out


def city_pair_camera(size_hw: tuple[int, int]) -> Calibration:
    """The city pair's camera file: its published (normalised) intrinsics at ``size_hw``, no mounting."""
    k = json.loads((REAL / "manydepth_pair" / "intrinsics_normalised.json").read_text())
    K = np.array(k["K"] if isinstance(k, dict) and "K" in k else k, dtype=float)
    h, w = size_hw
    return Calibration.of(Intrinsics(K[0, 0] * w, K[1, 1] * h, K[0, 2] * w, K[1, 2] * h, w, h), (), None)


def run_model(engine: Engine, src: Source) -> list[np.ndarray]:
    """The tinted raw frames ``src.shown`` as ``bsn-run`` would see them with ``engine``."""
    state = CameraState(engine.card, src.calibration)
    out = {}
    for i, frame in enumerate(src.frames):
        state.observe(frame)
        mf = state.frame_for(frame)
        if i not in src.shown:
            continue
        prob, _ = engine.infer(mf.to_model(frame)[None])
        mask = mf.to_raw(prob) >= engine.threshold
        scale = WIDTH / frame.shape[1]
        size = (WIDTH, round(frame.shape[0] * scale))
        img = cv2.resize(frame, size, interpolation=cv2.INTER_AREA)
        m = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
        out[i] = tint(img, m)
    return [out[i] for i in src.shown]


def _label(img: np.ndarray, text: str) -> np.ndarray:
    img = img.copy()
    cv2.putText(img, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def figure(columns: dict[str, list[np.ndarray]]) -> np.ndarray:
    """Rows of frames, one column per model, a white gap between."""
    rows = []
    for r in range(len(next(iter(columns.values())))):
        cells = [_label(col[r], name) for name, col in columns.items()]
        gap = np.full((cells[0].shape[0], 6, 3), 255, np.uint8)
        rows.append(np.hstack([c for cell in cells for c in (cell, gap)][:-1]))
        rows.append(np.full((6, rows[-1].shape[1], 3), 255, np.uint8))
    return np.vstack(rows[:-1])


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--model", action="append", metavar="[NAME=]MODEL.onnx",
                   help="exported models, one column each (default: the shipped one)")
    p.add_argument("--name", default="realview", help="the report's name in --out")
    return p


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    if not REAL.is_dir():
        print(f"no real data at {REAL}: nothing to show")
        return None
    try:
        models = {name: load_engine(path) for name, path in named(args.model or [str(DEFAULT_MODEL)]).items()}
    except ValueError as e:
        p.error(str(e))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# Real images by eye", "",
             "Blind spots (red) of each model at its own threshold, on the raw frames of every real source in "
             "`../shared/data/real/`, each seen as `bsn-run` sees it. Each picture carries the source and licence of "
             "its frames. Columns: " + ", ".join(models) + ".", ""]
    result: dict = {"models": {n: e.threshold for n, e in models.items()}, "sources": {}}
    for src in sources():
        cols = {name: run_model(engine, src) for name, engine in models.items()}
        fname = f"realview_{src.name.replace(' ', '_')}.jpg"
        cv2.imwrite(str(out / fname), figure(cols), [cv2.IMWRITE_JPEG_QUALITY, 88])
        result["sources"][src.name] = {"frames": src.shown, "camera": src.what, "figure": fname}
        shown = ", ".join(map(str, src.shown))
        lines += [f"## {src.name} ({src.what}; frames {shown})", "", f"![{src.name}]({fname})", "",
                  f"Frames: {licence(src.name).rstrip('.')}.", ""]
    return Report(result, lines, lines)


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
