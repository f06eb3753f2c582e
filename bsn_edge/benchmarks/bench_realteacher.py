"""Real occluders and road as segmentation teachers label them: the hand-drawn boxes of ``realboxes``.

    python -m bsn_edge.benchmarks.bench_realteacher --out benchmarks/results [--teacher NAME=RUN ...]

A teacher's labels are what distillation teaches B and what ``bsn-adapt`` labels a user's drives with,
so a teacher that misreads real streets misleads both. Each teacher sees each frame of
``bsn_edge/benchmarks/realboxes/boxes.json`` as training showed it frames: warped into the model camera as
``bsn-run`` warps it (the shipped model's camera, the frame's camera file or, without one, online
calibration over the frames before it), at the teacher's own input scale. Its labels are taken back
to the raw frame and scored per box: the share of an occluder's box labelled as its kind (a vehicle:
car, truck, bus, train or motorcycle; a person: person or rider; a cyclist: person, rider or
bicycle), **seen** when that share is at least ``realboxes``' marked share; and the share of open-road
box pixels labelled road. No threshold is tuned here.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from bsn_edge import semantics as sm
from bsn_edge.card import ModelCard
from bsn_edge.cli.common import CHECKOUT
from bsn_edge.data.dataset import IMAGENET_MEAN, IMAGENET_STD
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.export.seal import read_card
from bsn_edge.train.run import Run

from .bench_realboxes import (
    BOXES,
    GROUPS,
    MARKED_SHARE,
    OCCLUDERS,
    Frame,
    boxed,
    frac,
    load_frames,
    model_frame,
)
from .common import named
from .real_samples import REAL
from .runner import Report, run

KINDS = {"vehicle": (sm.CAR, sm.TRUCK, sm.BUS, sm.TRAIN, sm.MOTORCYCLE), "person": (sm.PERSON, sm.RIDER),
         "cyclist": (sm.PERSON, sm.RIDER, sm.BICYCLE), "road": (sm.ROAD,)}
KIND_OF = {"car": "vehicle", "truck": "vehicle", "bus": "vehicle", "person": "person", "cyclist": "cyclist",
           "open_road": "road"}


def labels(teacher: torch.nn.Module, scale: float, image: np.ndarray) -> np.ndarray:
    """The teacher's trainIds for a model-camera BGR ``image``, at its size; ``scale`` as in training."""
    rgb = image[..., ::-1].astype(np.float32) / 255.0
    x = torch.from_numpy(((rgb - IMAGENET_MEAN) / IMAGENET_STD).transpose(2, 0, 1).copy())[None]
    if scale != 1.0:
        x = F.interpolate(x, scale_factor=scale, mode="bilinear", align_corners=False)
    with torch.no_grad():
        logits = teacher(x)[0]
    logits = F.interpolate(logits, size=image.shape[:2], mode="bilinear", align_corners=False)
    return logits.argmax(1)[0].numpy().astype(np.uint8)


def kind_masks(card: ModelCard, frame: Frame, teacher: torch.nn.Module, scale: float) -> tuple[dict[str, np.ndarray],
                                                                                               np.ndarray]:
    """Each kind's mask on ``frame``'s raw pixels, and the labels in colour there (black outside the
    model camera's view)."""
    mf = model_frame(card, frame)
    ids = labels(teacher, scale, mf.to_model(frame.image))
    masks = {k: mf.to_raw(np.isin(ids, ids_).astype(np.float32)) >= 0.5 for k, ids_ in KINDS.items()}
    masks["view"] = mf.to_raw(np.ones(ids.shape, np.float32)) >= 0.5
    colour = mf.to_raw(sm.colorize(ids), cv2.INTER_NEAREST)
    return masks, colour


# per-class IoU on CamVid's held-out drive: the teacher's trainIds against CamVid's labels as trainIds
IOU_CLASSES = {"road": (sm.ROAD,), "pavement": (sm.SIDEWALK,), "vehicle": KINDS["vehicle"],
               "person and cyclist": KINDS["cyclist"]}


def camvid_iou(card: ModelCard, teacher: torch.nn.Module, scale: float) -> dict[str, Any]:
    """Per-class IoU of the teacher on CamVid's held-out drive, each frame warped as ``bsn-run`` warps a
    folder with no camera file and labelled at the teacher's scale, compared on the raw pixels the model
    camera sees that CamVid labels (its unlabelled pixels left out)."""
    from bsn_edge.labels import camvid
    from bsn_edge.runtime.camera_state import CameraState

    state = CameraState(card, None, background=False)
    inter, union = dict.fromkeys(IOU_CLASSES, 0), dict.fromkeys(IOU_CLASSES, 0)
    frames = list(camvid.frames_of(REAL / "camvid", camvid.HELD_OUT, "train"))
    for fr in frames:
        image, truth = fr.rgb(), fr.semantic()
        state.observe(image)
        mf = state.frame_for(image)
        ids = mf.to_raw(labels(teacher, scale, mf.to_model(image)), cv2.INTER_NEAREST)
        seen = (mf.to_raw(np.ones(card.input_size, np.float32)) >= 0.5) & (truth != sm.IGNORE)
        for name, cls in IOU_CLASSES.items():
            a, b = np.isin(ids, cls) & seen, np.isin(truth, cls) & seen
            inter[name] += int((a & b).sum())
            union[name] += int((a | b).sum())
    state.close()
    return {"frames": len(frames), "iou": {k: round(inter[k] / max(union[k], 1), 3) for k in IOU_CLASSES}}


def outside(masks: dict[str, np.ndarray], boxes: list[dict[str, Any]]) -> tuple[int, int]:
    """Pixels labelled vehicle or person outside every occluder box, and pixels in view: the boxes hold
    every occluder that hides road, so this bounds the labels that see one where there is none."""
    free = masks["view"].copy()
    for b in boxes:
        if b["class"] != "open_road":
            x0, y0, x1, y1 = b["box"]
            free[y0:y1, x0:x1] = False
    found = (masks["vehicle"] | masks["cyclist"]) & free
    return int(found.sum()), int(masks["view"].sum())


def score(masks: dict[str, np.ndarray], boxes: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each box with the share of its pixels labelled as its kind; occluders seen or not."""
    out = []
    for b in boxes:
        x0, y0, x1, y1 = b["box"]
        m = masks[KIND_OF[b["class"]]]
        row = {**b, "share": round(float(m[y0:y1, x0:x1].mean()) if x1 > x0 and y1 > y0 else 0.0, 4)}
        if b["class"] != "open_road":
            row["seen"] = row["share"] >= MARKED_SHARE
        out.append(row)
    return out


def summary(rows: list[dict[str, Any]], elsewhere: list[tuple[int, int]]) -> dict[str, Any]:
    """Near and all occluders seen, by group, their mean share, open road labelled road
    (pixel-weighted), and vehicles or people labelled outside the boxes (share of the pixels in view,
    from :func:`outside` per frame)."""
    occ = [r for r in rows if r["class"] in OCCLUDERS]
    out: dict[str, Any] = {"groups": {}}
    for key, rs in (("near", [r for r in occ if r.get("near")]), ("all", occ)):
        out[key] = [sum(r["seen"] for r in rs), len(rs)]
        out[f"{key}_mean_share"] = round(float(np.mean([r["share"] for r in rs])), 4) if rs else None
    for g, classes in GROUPS.items():
        rs = [r for r in occ if r["class"] in classes]
        out["groups"][g] = {"near": [sum(r["seen"] for r in rs if r.get("near")), sum(bool(r.get("near")) for r in rs)],
                            "all": [sum(r["seen"] for r in rs), len(rs)]}
    road = [r for r in rows if r["class"] == "open_road"]
    area = [(r["box"][2] - r["box"][0]) * (r["box"][3] - r["box"][1]) for r in road]
    out["open_road_labelled_road"] = round(sum(r["share"] * a for r, a in zip(road, area, strict=True))
                                           / max(sum(area), 1), 4)
    out["objects_outside_boxes"] = round(sum(f for f, _ in elsewhere) / max(sum(v for _, v in elsewhere), 1), 4)
    return out


def panel(image: np.ndarray, colour: np.ndarray, rows: list[dict[str, Any]], title: str) -> np.ndarray:
    """The frame under the teacher's labels (half and half) with each box: green seen, orange missed,
    blue open road."""
    return boxed(cv2.addWeighted(image, 0.5, colour, 0.5, 0.0), rows, "seen", title)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--teacher", action="append", metavar="[NAME=]RUN",
                   help="runs whose teachers are scored side by side (a run, a teacher-only run or a shipped run; "
                        "default: the shipped default's, models/default)")
    p.add_argument("--name", default="realteacher", help="the report's name in --out")
    return p


def _teachers(p: argparse.ArgumentParser, specs: list[str] | None) -> dict[str, tuple[Any, float, str, bool]]:
    """Each teacher ``--teacher`` names: (network, input scale, encoder, pretrained)."""
    teachers = {}
    try:
        named_specs = named(specs or [f"default={CHECKOUT / 'models' / 'default'}"])
    except ValueError as e:
        p.error(str(e))
    for name, path in named_specs.items():
        run = Run(path)
        teacher = run.load_teacher()
        if teacher is None:
            raise SystemExit(f"{path}: no teacher there")
        holder = run.teacher_holder()
        if holder is None:
            raise SystemExit(f"{path}: no teacher's run there")
        built = holder.teacher_config()
        teachers[name or Path(path).name] = (teacher, built.scale, built.encoder, built.pretrained)
    return teachers


def _frames(card, frames: list, teachers: dict, out: Path, report: str, result: dict[str, Any]):
    """Every frame labelled by every teacher and scored on its boxes, its picture written; the rows by
    teacher, the labels outside the boxes by teacher, and the report's frame section."""
    per: dict[str, list[dict[str, Any]]] = defaultdict(list)
    elsewhere: dict[str, list[tuple[int, int]]] = defaultdict(list)
    lines = []
    for k, fr in enumerate(frames):
        cells = []
        for name, (teacher, scale, _, _) in teachers.items():
            masks, colour = kind_masks(card, fr, teacher, scale)
            rows = score(masks, fr.boxes)
            per[name] += rows
            elsewhere[name].append(outside(masks, fr.boxes))
            result["frames"].setdefault(fr.name, {})[name] = rows
            cells.append(panel(fr.image, colour, rows, name))
        gap = np.full((cells[0].shape[0], 6, 3), 255, np.uint8)
        fname = f"{report}_{k:02d}.jpg"
        out.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(out / fname), np.hstack([c for cell in cells for c in (cell, gap)][:-1]),
                    [cv2.IMWRITE_JPEG_QUALITY, 85])
        lines += [f"### {fr.name}", "", f"![{fr.name}]({fname})", "", f"Frames: {fr.credit.rstrip('.')}.", ""]
    return per, elsewhere, lines


def _box_table(teachers: dict, per: dict, elsewhere: dict, result: dict[str, Any]) -> list[str]:
    table = ["| teacher (encoder) | near occluders seen | all occluders seen | mean share of the box, near / all | "
             "vehicles near / all | people near / all | cyclists near / all | open road labelled road | "
             "vehicle or person outside the boxes |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, (_, scale, encoder, pretrained) in teachers.items():
        s = summary(per[name], elsewhere[name])
        result["teachers"][name] = {"encoder": encoder, "pretrained": pretrained, "scale": scale, **s}
        g = s["groups"]
        table.append(f"| {name} ({encoder}{', ImageNet' if pretrained else ''}) | {frac(s['near'])} | "
                     f"{frac(s['all'])} | {100 * s['near_mean_share']:.0f} % / {100 * s['all_mean_share']:.0f} % | "
                     f"{frac(g['vehicles']['near'])} / {frac(g['vehicles']['all'])} | "
                     f"{frac(g['people']['near'])} / {frac(g['people']['all'])} | "
                     f"{frac(g['cyclists']['near'])} / {frac(g['cyclists']['all'])} | "
                     f"{100 * s['open_road_labelled_road']:.1f} % | {100 * s['objects_outside_boxes']:.1f} % |")
    return table


def _camvid_section(card, teachers: dict, result: dict[str, Any]) -> list[str]:
    """Each teacher's per-class IoU on CamVid's held-out drive (nothing when CamVid is not at hand)."""
    cv_table = ["| teacher (encoder) | " + " | ".join(IOU_CLASSES) + " |", "|---|" + "---|" * len(IOU_CLASSES)]
    cv_frames = 0
    if (REAL / "camvid").is_dir():
        for name, (teacher, scale, encoder, pretrained) in teachers.items():
            r = camvid_iou(card, teacher, scale)
            cv_frames = r["frames"]
            result["teachers"][name]["camvid_iou"] = r["iou"]
            cv_table.append(f"| {name} ({encoder}{', ImageNet' if pretrained else ''}) | "
                            + " | ".join(f"{r['iou'][k]:.3f}" for k in IOU_CLASSES) + " |")
    if not cv_frames:
        return []
    return ["## CamVid's held-out drive, per class", "",
            f"IoU on CamVid's held-out drive, {cv_frames} labelled frames (kept out of every training "
            "run), each warped as `bsn-run` warps a folder with no camera file and compared on the raw pixels "
            "the model camera sees that CamVid labels. Vehicle: car, truck, bus, train, motorcycle; person and "
            "cyclist: person, rider, bicycle (CamVid's pedestrian and bicyclist).", "", *cv_table, ""]


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    if not REAL.is_dir():
        print(f"no real data at {REAL}: nothing to score")
        return None
    teachers = _teachers(p, args.teacher)
    card = read_card(DEFAULT_MODEL)
    frames = load_frames(json.loads(BOXES.read_text()))
    result: dict[str, Any] = {"seen_share": MARKED_SHARE, "teachers": {}, "frames": {}}
    per, elsewhere, lines = _frames(card, frames, teachers, Path(args.out), args.name, result)
    table = _box_table(teachers, per, elsewhere, result)
    camvid_md = _camvid_section(card, teachers, result)
    md = ["# Real occluders and road as the segmentation teachers label them", "",
          f"{len(frames)} real frames, the boxes of `realboxes` (`bsn_edge/benchmarks/realboxes/boxes.json`). Each "
          "frame is "
          "warped into the shipped model's camera as `bsn-run` warps it and labelled by each teacher at its own "
          f"input scale. An occluder is seen when at least {100 * MARKED_SHARE:.0f} % of its box is labelled as its "
          "kind (vehicle: car, truck, bus, train, motorcycle; person: person, rider; cyclist: those and bicycle); "
          "open road labelled road is pixel-weighted over the open-road boxes. The boxes hold every occluder that "
          "hides road, so vehicle or person labelled outside them (share of the pixels in the model camera's view) "
          "bounds what a teacher sees where there is none (hedges, tree lines and shadows read as cars, poles as "
          "people; a parked car that hides no road counts there too). In the pictures, the labels in "
          "Cityscapes colours over the frame; boxes green seen, orange missed, blue open road.", "",
          *table, "", *camvid_md, "## Frames", "", *lines]
    return Report(result, md, table)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
