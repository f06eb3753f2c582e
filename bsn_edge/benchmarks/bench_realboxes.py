"""Real occluders marked: hand-drawn boxes on the development footage, scored for each model.

    python -m bsn_edge.benchmarks.bench_realboxes --out benchmarks/results [--model A.onnx --model NAME=B.onnx]

``bsn_edge/benchmarks/realboxes/boxes.json`` holds boxes drawn by hand on raw frames of every real source in
``../shared/data/real/`` (DDAD's front and side cameras, the city pair, the Udacity, highway,
mountain, challenge and garage clips), before any model's output on those frames was looked at:
every occluder that hides road (car, truck, bus, person, cyclist), near (within about 20 m) or far,
and boxes of open road that must stay clear. Each model sees each frame the way ``bsn-run`` would
(``CameraState``): DDAD with its calibration, the Udacity clip with the product's own calibration
steps, the city pair with its published intrinsics, the other clips with no camera file (online
calibration over the frames up to the one scored). Blind spots are taken at the model's own
threshold, on the raw frame. An occluder counts as **marked** when at least :data:`MARKED_SHARE` of
its box is blind spot; **open road flagged** is the share of open-road box pixels that are blind
spot. No threshold is tuned here: every figure is at the model card's threshold.

``--withhold-camera`` scores the frames that have a camera file twice per model, with it and
without it (a camera nobody calibrated, as ``bsn-run`` takes one): what a user without a camera
file loses.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.calibration import Calibration
from bsn_edge.calibration.exif import from_exif
from bsn_edge.card import ModelCard
from bsn_edge.model_frame import ModelFrame
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.sequence.images import read_image
from bsn_edge.sequence.media import read_video

from .bench_realview import city_pair_camera
from .common import engines, models_parser
from .real_samples import REAL, ddad_samples, licence, udacity_camera
from .runner import Report, run

BOXES = Path(__file__).resolve().parent / "realboxes" / "boxes.json"
MARKED_SHARE = 0.15          # of an occluder's box at the threshold: marked
OCCLUDERS = ("car", "truck", "bus", "person", "cyclist")
GROUPS = {"vehicles": ("car", "truck", "bus"), "people": ("person",), "cyclists": ("cyclist",)}
PANEL_WIDTH = 640


class Frame:
    """One scored frame: the frames fed before it (online calibration), its camera file, its boxes,
    and its file when it is a picture (whose EXIF ``bsn-run`` reads when there is no camera file)."""

    def __init__(self, name: str, frames: list[np.ndarray], calibration: Calibration | None,
                 boxes: list[dict[str, Any]], credit: str, picture: Path | None = None) -> None:
        self.name, self.frames, self.calibration, self.boxes, self.credit = name, frames, calibration, boxes, credit
        self.picture = picture

    @property
    def image(self) -> np.ndarray:
        return self.frames[-1]


def load_frames(spec: dict[str, Any]) -> list[Frame]:
    """The frames ``boxes.json`` names, with the camera ``bsn-run`` would be given for each."""
    out = []
    ddad = {s.name: s for s in [*ddad_samples("front"), *ddad_samples("other")]}
    udacity = None
    for f in spec["frames"]:
        if f["source"] == "ddad":
            first = sorted((REAL / "ddad_dgp" / f["scene"] / "rgb" / f["camera"]).glob("*.jpg"))[0].stem
            name = f"ddad {f['scene']} {first}" + ("" if f["camera"] == "CAMERA_01" else f" {f['camera']}")
            s = ddad[name]
            out.append(Frame(name, [s.image], s.camera, f["boxes"], licence("ddad")))
            continue
        path = REAL / f["file"]
        if f["source"] == "video":
            frames = read_video(path, f["frame"] + 1)
            name = f"{path.stem} frame {f['frame']}"
        else:
            frames = [read_image(path)]
            name = f["file"]
        if f["camera"] == "udacity":
            udacity = udacity or udacity_camera()[1]
            cal, credit = udacity, licence("udacity")
        elif f["camera"] == "city pair":
            cal, credit = city_pair_camera(frames[-1].shape[:2]), licence("city pair")
        else:
            cal = None
            key = path.parent.name if f["source"] == "image" else path.stem
            credit = licence({"udacity_test_video": "udacity"}.get(key, key))
        if tuple(frames[-1].shape[1::-1]) != tuple(f["size"]):
            raise ValueError(f"{name}: the boxes were drawn on {f['size']} but the frame is "
                             f"{frames[-1].shape[1]}x{frames[-1].shape[0]}")
        out.append(Frame(name, frames, cal, f["boxes"], credit, path if f["source"] == "image" else None))
    return out


def model_frame(card: ModelCard, frame: Frame, withheld: bool = False) -> ModelFrame:
    """How ``bsn-run`` warps ``frame`` into ``card``'s model camera after the frames fed before it
    (``withheld``: as it does when the user gives no camera file)."""
    cal, exif = frame.calibration, None
    if withheld:
        h, w = frame.image.shape[:2]
        cal = exif = from_exif(frame.picture, w, h) if frame.picture is not None else None
    state = CameraState(card, cal, background=False,   # the estimate of these frames
                        intrinsics_from=exif.intrinsics_method if exif is not None else "camera file")
    mf = None
    for f in frame.frames:
        state.observe(f)
        mf = state.frame_for(f)
    state.close()
    if mf is None:
        raise ValueError(f"{frame}: no picture to warp")
    return mf


def blind_spots(engine: Engine, frame: Frame, withheld: bool = False) -> np.ndarray:
    """The blind-spot mask on ``frame``'s raw pixels at the model's threshold, as ``bsn-run`` sees it
    (``withheld``: as it sees it when the user gives no camera file)."""
    mf = model_frame(engine.card, frame, withheld)
    prob, _ = engine.infer(mf.to_model(frame.image)[None])
    return mf.to_raw(prob) >= engine.threshold


def score(mask: np.ndarray, boxes: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each box with the share of its pixels that are blind spot, and for occluders, marked or not."""
    out = []
    for b in boxes:
        x0, y0, x1, y1 = b["box"]
        share = float(mask[y0:y1, x0:x1].mean()) if x1 > x0 and y1 > y0 else 0.0
        row = {**b, "share": round(share, 4)}
        if b["class"] != "open_road":
            row["marked"] = share >= MARKED_SHARE
        out.append(row)
    return out


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Near and all occluders marked, by group, and the open road flagged (pixel-weighted)."""
    occ = [r for r in rows if r["class"] in OCCLUDERS]
    near = [r for r in occ if r.get("near")]
    out: dict[str, Any] = {"near": [sum(r["marked"] for r in near), len(near)],
                           "all": [sum(r["marked"] for r in occ), len(occ)], "groups": {}}
    for g, classes in GROUPS.items():
        rs = [r for r in occ if r["class"] in classes]
        near_g = [r for r in rs if r.get("near")]
        out["groups"][g] = {"near": [sum(r["marked"] for r in near_g), len(near_g)],
                            "all": [sum(r["marked"] for r in rs), len(rs)]}
    road = [r for r in rows if r["class"] == "open_road"]
    area = [(r["box"][2] - r["box"][0]) * (r["box"][3] - r["box"][1]) for r in road]
    flagged = sum(r["share"] * a for r, a in zip(road, area, strict=True))
    out["open_road_flagged"] = round(flagged / max(sum(area), 1), 4)
    out["open_road_boxes_over_2pct"] = [sum(r["share"] > 0.02 for r in road), len(road)]
    return out


def panel(image: np.ndarray, mask: np.ndarray, rows: list[dict[str, Any]], title: str) -> np.ndarray:
    """The frame with its blind spots in red and each box: green marked, orange missed, blue open road."""
    img = image.copy()
    img[mask] = (0.45 * img[mask] + 0.55 * np.array([0, 0, 255])).astype(np.uint8)
    return boxed(img, rows, "marked", title)


def boxed(img: np.ndarray, rows: list[dict[str, Any]], hit: str, title: str) -> np.ndarray:
    """``img`` (drawn on) with each box of ``rows``: green where ``hit`` is true, orange where not,
    blue open road; resized to the report's width and titled."""
    for r in rows:
        x0, y0, x1, y1 = r["box"]
        colour = (255, 128, 0) if r["class"] == "open_road" else (0, 200, 0) if r[hit] else (0, 140, 255)
        cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), colour, max(1, img.shape[1] // 400))
    s = PANEL_WIDTH / img.shape[1]
    img = cv2.resize(img, (PANEL_WIDTH, round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
    cv2.putText(img, title, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, title, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def frac(pair: list[int]) -> str:
    return f"{pair[0]} of {pair[1]}" + (f" ({100 * pair[0] / pair[1]:.0f} %)" if pair[1] else "")


def parser() -> argparse.ArgumentParser:
    p = models_parser(__doc__, "realboxes")
    p.add_argument("--withhold-camera", action="store_true",
                   help="score only the frames that have a camera file, each model twice: with it, and as bsn-run "
                        "sees them without one")
    return p


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    if not REAL.is_dir():
        print(f"no real data at {REAL}: nothing to score")
        return None
    models = engines(p, args.model)
    frames = load_frames(json.loads(BOXES.read_text()))
    runs = [(name, engine, False) for name, engine in models.items()]
    if args.withhold_camera:
        frames = [f for f in frames if f.calibration is not None]
        runs = [(f"{name}{', no camera file' if w else ''}", engine, w) for name, engine in models.items()
                for w in (False, True)]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {"marked_share": MARKED_SHARE, "models": {}, "frames": {}}
    per_model: dict[str, list[dict[str, Any]]] = defaultdict(list)
    lines = []
    for k, fr in enumerate(frames):
        cells = []
        for name, engine, withheld in runs:
            mask = blind_spots(engine, fr, withheld)
            rows = score(mask, fr.boxes)
            per_model[name] += rows
            result["frames"].setdefault(fr.name, {})[name] = rows
            cells.append(panel(fr.image, mask, rows, name))
        gap = np.full((cells[0].shape[0], 6, 3), 255, np.uint8)
        fname = f"{args.name}_{k:02d}.jpg"
        cv2.imwrite(str(out / fname), np.hstack([c for cell in cells for c in (cell, gap)][:-1]),
                    [cv2.IMWRITE_JPEG_QUALITY, 85])
        lines += [f"### {fr.name}", "", f"![{fr.name}]({fname})", "", f"Frames: {fr.credit.rstrip('.')}.", ""]
    table = ["| model (threshold) | near occluders marked | all occluders marked | vehicles near / all | "
             "people near / all | cyclists near / all | open road flagged (boxes over 2 %) |",
             "|---|---|---|---|---|---|---|"]
    for name, engine, _ in runs:
        s = summary(per_model[name])
        result["models"][name] = {"threshold": engine.threshold, **s}
        g = s["groups"]
        table.append(f"| {name} ({engine.threshold:.2f}) | {frac(s['near'])} | {frac(s['all'])} | "
                     f"{frac(g['vehicles']['near'])} / {frac(g['vehicles']['all'])} | "
                     f"{frac(g['people']['near'])} / {frac(g['people']['all'])} | "
                     f"{frac(g['cyclists']['near'])} / {frac(g['cyclists']['all'])} | "
                     f"{100 * s['open_road_flagged']:.1f} % ({frac(s['open_road_boxes_over_2pct'])}) |")
    withheld_note = (" Only the frames that have a camera file are scored, each model with it and without it "
                "(as `bsn-run` sees a camera nobody calibrated: the model camera's intrinsics rescaled, online "
                "calibration over the frames fed, the hood looked for).") if args.withhold_camera else ""
    md = ["# Real occluders marked: hand-drawn boxes on the development footage", "",
          f"{len(frames)} real frames, boxes from `bsn_edge/benchmarks/realboxes/boxes.json` (drawn before any model's "
          f"output on them was seen). An occluder is marked when at least {100 * MARKED_SHARE:.0f} % of its box is "
          "blind spot at the model's threshold; open road flagged is the share of open-road box pixels that are. "
          "Boxes in the pictures: green marked, orange missed, blue open road; blind spots in red." + withheld_note, "",
          *table, "", "## Frames", "", *lines]
    return Report(result, md, table)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
