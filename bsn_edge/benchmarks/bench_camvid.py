"""Real road users marked on CamVid's held-out drive, by pixel labels: every model side by side.

    python -m bsn_edge.benchmarks.bench_camvid --out benchmarks/results [--model A.onnx --model NAME=B.onnx]

The drive ``0006R0`` (101 labelled frames, 1 s apart) is kept out of everything trained. Each model sees
its frames as ``bsn-run`` sees a folder of them with no camera file (``CameraState``: the model camera's
field of view, the first guess and online calibration over the frames in order), and its blind spots
are taken at the card's threshold on the raw frame. A **road user** is an 8-connected region of the
label's car (vehicles) or pedestrian and bicyclist (people) pixels; it counts as **marked** when at least
:data:`MARKED_SHARE` of its pixels are blind spot (the rule of ``bench_realboxes``). **Near**: at least
:data:`NEAR_PIXELS` pixels with its lowest row in the lower :data:`LOWER_SHARE` of the frame (at 480x360);
**all**: at least :data:`ALL_PIXELS` pixels. **Open road flagged**: the share of road pixels in the lower
part, at least :data:`CLEAR_PX` pixels from anything but road or pavement, that are blind spot.

**Where the flagged pixels fall**: of every pixel flagged over the drive, the share on road users (car,
pedestrian, bicyclist), on buildings and trees (with poles, signs and fences), on sky, on road and pavement,
and unlabelled; and the share of the frame flagged. A model must not win marks by flagging more of everything:
``--like-area`` also scores every model after the first at the threshold that flags the same share of the
drive's pixels as the first does at its own (the first is the reference, the shipped default by convention).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.calibration import Calibration
from bsn_edge.labels import camvid
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine

from .bench_realboxes import frac
from .common import engines, models_parser
from .real_samples import REAL, licence
from .runner import Report, run

MARKED_SHARE = 0.15
NEAR_PIXELS = 1500
ALL_PIXELS = 200
LOWER_SHARE = 0.4
CLEAR_PX = 25
GROUPS = {"vehicles": (8,), "people": (9, 10)}       # CamVid ids: car; pedestrian, bicyclist
GROUND = (3, 4)                                      # road, pavement
ROAD = 3
# where a flagged pixel falls, by CamVid id (:data:`camvid.CAMVID_CLASSES`)
FALLS = {"road users": (8, 9, 10), "buildings and trees": (1, 2, 5, 6, 7), "sky": (0,), "road and pavement": GROUND,
         "unlabelled": (11,)}


def road_users(label: np.ndarray) -> list[dict[str, Any]]:
    """The label's road users: group, pixel mask, area, and whether near (480x360 thresholds scaled)."""
    h, w = label.shape
    scale = (h * w) / (480 * 360)
    out = []
    for group, ids in GROUPS.items():
        n, lab, stats, _ = cv2.connectedComponentsWithStats(np.isin(label, ids).astype(np.uint8), connectivity=8)
        for k in range(1, n):
            area = int(stats[k, cv2.CC_STAT_AREA])
            if area < ALL_PIXELS * scale:
                continue
            bottom = int(stats[k, cv2.CC_STAT_TOP] + stats[k, cv2.CC_STAT_HEIGHT] - 1)
            out.append({"group": group, "mask": lab == k, "area": area,
                        "near": area >= NEAR_PIXELS * scale and bottom >= (1 - LOWER_SHARE) * h})
    return out


def open_road(label: np.ndarray) -> np.ndarray:
    """Road pixels in the lower part of the frame, at least ``CLEAR_PX`` from anything but road or pavement."""
    h = label.shape[0]
    other = (~np.isin(label, GROUND)).astype(np.uint8)
    far = cv2.distanceTransform(1 - other, cv2.DIST_L2, 5) >= CLEAR_PX
    lower = np.zeros_like(far)
    lower[round((1 - LOWER_SHARE) * h):] = True
    return (label == ROAD) & far & lower


def assumed_camera_file(engine: Engine, frame: camvid.CamVidFrame) -> Calibration:
    """A camera file that says only what ``bsn-run`` assumes of a camera it knows nothing of: the model
    camera's field of view at the frame's size, sitting as the model camera does (its height and pitch,
    no yaw or roll)."""
    h, w = frame.rgb().shape[:2]
    return Calibration.of(engine.card.camera.scaled(w, h), (), engine.card.mounting, method="assumed")


def infer_drive(engine: Engine, frames: list[camvid.CamVidFrame],
                assumed: bool = False) -> tuple[list[np.ndarray], dict[str, Any] | None]:
    """Every frame of the drive through ``engine`` as ``bsn-run`` would run the folder (``assumed``: with
    :func:`assumed_camera_file` instead of none, so no first guess and no online calibration): each frame's
    blind-spot probability on the raw frame (float16), and the camera's first guess."""
    cal = assumed_camera_file(engine, frames[0]) if assumed else None
    state = CameraState(engine.card, cal, background=False)
    probs = []
    for fr in frames:
        image = fr.rgb()
        state.observe(image)
        mf = state.frame_for(image)
        prob, _ = engine.infer(mf.to_model(image)[None])
        probs.append(mf.to_raw(prob).astype(np.float16))
    state.close()
    return probs, state.summary().get("first_guess")


def score_masks(probs: list[np.ndarray], labels: list[np.ndarray], threshold: float,
                masks: dict[int, np.ndarray] | None = None) -> dict[str, Any]:
    """Road users marked, open road flagged and where the flagged pixels fall, at ``threshold``. ``masks``:
    filled with the blind-spot mask of each frame (by its index) that has near people or cyclists."""
    counts: dict[str, list[int]] = {f"{g}_{r}": [0, 0] for g in GROUPS for r in ("near", "all")}
    flagged_road, road_px, flagged_all, pixels = 0, 0, 0, 0
    falls = dict.fromkeys(FALLS, 0)
    for k, (prob, label) in enumerate(zip(probs, labels, strict=True)):
        mask = prob >= threshold
        users = road_users(label)
        if masks is not None and any(u["near"] and u["group"] == "people" for u in users):
            masks[k] = mask
        for u in users:
            marked = int(mask[u["mask"]].mean() >= MARKED_SHARE)
            for r in ("near", "all") if u["near"] else ("all",):
                counts[f"{u['group']}_{r}"][0] += marked
                counts[f"{u['group']}_{r}"][1] += 1
        clear = open_road(label)
        flagged_road += int(mask[clear].sum())
        road_px += int(clear.sum())
        flagged_all += int(mask.sum())
        pixels += mask.size
        for where, ids in FALLS.items():
            falls[where] += int(mask[np.isin(label, ids)].sum())
    counts["road_users_all"] = [sum(counts[f"{g}_all"][i] for g in GROUPS) for i in (0, 1)]
    return {"threshold": round(float(threshold), 4), "counts": counts,
            "open_road_flagged": round(flagged_road / max(road_px, 1), 4),
            "flagged": round(flagged_all / max(pixels, 1), 4),
            "falls": {k: round(v / max(flagged_all, 1), 4) for k, v in falls.items()}}


def like_area_threshold(probs: list[np.ndarray], share: float) -> float:
    """The threshold at which ``probs`` flag ``share`` of their pixels (the reference's flagged share)."""
    values = np.concatenate([p.ravel() for p in probs]).astype(np.float32)
    return float(np.quantile(values, 1.0 - share)) if share > 0 else float(values.max()) + 1e-6


def score_drive(engine: Engine, frames: list[camvid.CamVidFrame], assumed: bool = False,
                masks: dict[int, np.ndarray] | None = None) -> dict[str, Any]:
    """The drive through ``engine`` (:func:`infer_drive`), scored at the card's threshold (:func:`score_masks`),
    with the camera's first guess."""
    probs, guess = infer_drive(engine, frames, assumed)
    labels = [fr.camvid_label() for fr in frames]
    return {**score_masks(probs, labels, engine.threshold, masks), "camera": guess}


def people_pictures(frames: list[camvid.CamVidFrame], masks: dict[str, dict[int, np.ndarray]], out: Path,
                    name: str) -> list[str]:
    """For the eye: each frame with near people or cyclists, every model's blind spots (red) side by side, the
    near people and cyclists outlined (green); the pictures' report lines. They stay on the machine, as the
    real frames do."""
    lines = []
    for k in sorted(next(iter(masks.values()), {})):
        image, label = frames[k].rgb(), frames[k].camvid_label()
        near = [u for u in road_users(label) if u["near"] and u["group"] == "people"]
        cells = []
        for model, by_frame in masks.items():
            img = image.copy()
            m = by_frame[k]
            img[m] = (0.5 * img[m] + 0.5 * np.array([0, 0, 255])).astype(np.uint8)
            for u in near:
                cnts, _ = cv2.findContours(u["mask"].astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
                cv2.drawContours(img, cnts, -1, (0, 255, 0), 1)
            cv2.putText(img, model, (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2, cv2.LINE_AA)
            cells.append(img)
        fname = f"{name}_people_{k:03d}.jpg"
        cv2.imwrite(str(out / fname), np.hstack(cells), [cv2.IMWRITE_JPEG_QUALITY, 85])
        lines += [f"![frame {k}]({fname})", ""]
    return lines


def parser() -> argparse.ArgumentParser:
    p = models_parser(__doc__, "camvid")
    p.add_argument("--pictures", action="store_true",
                   help="also write, for each frame with near people or cyclists, every model's blind spots side "
                        "by side with those people outlined (for the eye; the pictures stay on the machine)")
    p.add_argument("--like-area", action="store_true",
                   help="also score every model after the first at the threshold that flags as much of the drive as "
                        "the first does at its own: a comparison at a like flagged area")
    p.add_argument("--drive", default=camvid.HELD_OUT, help=f"the drive scored (default {camvid.HELD_OUT})")
    p.add_argument("--assumed-camera", action="store_true",
                   help="also score each model with a camera file that says only what bsn-run assumes (the model "
                        "camera's field of view and mounting): what the first guess and online calibration win "
                        "or cost")
    return p


def table_row(name: str, r: dict[str, Any]) -> str:
    c = r["counts"]
    falls = " / ".join(f"{100 * r['falls'][k]:.0f}" for k in FALLS)
    return (f"| {name} ({r['threshold']:.2f}) | {frac(c['vehicles_near'])} | {frac(c['people_near'])} | "
            f"{frac(c['road_users_all'])} | {100 * r['open_road_flagged']:.1f} % | {100 * r['flagged']:.2f} % | "
            f"{falls} |")


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    root = REAL / "camvid"
    if not root.is_dir():
        print(f"no CamVid frames at {root}: nothing to score")
        return None
    models = engines(p, args.model)
    frames = list(camvid.frames_of(root, args.drive, "train"))
    labels = [fr.camvid_label() for fr in frames]
    result: dict[str, Any] = {"drive": args.drive, "frames": len(frames), "marked_share": MARKED_SHARE,
                              "models": {}}
    table = ["| model (threshold) | near cars | near people and cyclists | all road users | open road flagged | "
             f"frame flagged | flagged on {' / '.join(FALLS)} (%) |", "|---|---|---|---|---|---|---|"]
    runs = [(name, engine, False) for name, engine in models.items()]
    if args.assumed_camera:
        runs = [(f"{name}{', assumed camera file' if a else ''}", engine, a) for name, engine in models.items()
                for a in (False, True)]
    masks: dict[str, dict[int, np.ndarray]] = {}
    reference: float | None = None
    for name, engine, assumed in runs:
        probs, guess = infer_drive(engine, frames, assumed)
        r = score_masks(probs, labels, engine.threshold, masks.setdefault(name, {}) if args.pictures else None)
        result["models"][name] = {**r, "camera": guess}
        table.append(table_row(name, r))
        if args.like_area and reference is not None:
            like = score_masks(probs, labels, like_area_threshold(probs, reference))
            result["models"][name]["like_area"] = like
            table.append(table_row(f"{name} at the first's flagged area", like))
        reference = r["flagged"] if reference is None else reference
    md = [f"# Real road users marked: CamVid drive {args.drive}, by pixel labels", "",
          f"{len(frames)} labelled frames, 1 s apart, held out of every training run, each run as `bsn-run` runs a "
          f"folder with no camera file. A road user (an 8-connected region of car, or of pedestrian and bicyclist "
          f"pixels, at least {ALL_PIXELS} px) is marked when at least {100 * MARKED_SHARE:.0f} % of its pixels are "
          f"blind spot at the model's threshold; near: at least {NEAR_PIXELS} px with its lowest row in the lower "
          f"{100 * LOWER_SHARE:.0f} % of the 480x360 frame; open road: road pixels in that lower part at least "
          f"{CLEAR_PX} px from anything but road or pavement. Frame flagged: the share of the drive's pixels that "
          "are blind spot; then where those pixels fall, by the labels"
          + (" (rows 'at the first's flagged area': the model at the threshold that flags as much of the drive as "
             "the first row)" if args.like_area else "") + ".", "", *table, "",
          f"Frames and labels: {licence('camvid')}."]
    if args.pictures:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        md += ["", "## Near people and cyclists, each model side by side", "",
               "Blind spots in red, the near people and cyclists outlined in green.", "",
               *people_pictures(frames, masks, out, args.name)]
    return Report(result, md, table)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
