"""What the T-frame labels teach, per class: the positive pixels inside V that fall on each kind of road user,
for the real drives against the rendered clips.

    python -m bsn_edge.benchmarks.bench_label_classes --data ~/.cache/bsn-edge/campaign/data --out benchmarks/results

A blind spot of frame t lies on the pixels of what hides the road, so the class of a positive pixel (the
frame's own segmentation) is the occluder it teaches. For each world (clips whose folder name starts with
``camvid_``: real; the rest: rendered) and each group of classes: its share of the positive pixels in V,
positive pixels per labelled frame, the share of frames with any, and the positive rate of the group's
own pixels inside V (how often a pixel of that class is taught as hiding road). Every labelled frame is
read at the clip's own size; no timing.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.data.dataset import find_clips
from bsn_edge.sequence import read_mask
from bsn_edge.sequence.folder import SequenceFolder

from .common import machine
from .runner import RefusedError, Report, run

GROUPS: dict[str, tuple[int, ...]] = {
    "people and cyclists": sm.PEOPLE_AND_CYCLES,
    "cars": (sm.CAR,),
    "trucks, buses, trains": (sm.TRUCK, sm.BUS, sm.TRAIN),
    "buildings, walls, fences, poles": (sm.BUILDING, sm.WALL, sm.FENCE, sm.POLE, sm.TRAFFIC_LIGHT, sm.TRAFFIC_SIGN),
    "vegetation and terrain": (sm.VEGETATION, sm.TERRAIN),
    "road and sidewalk": (sm.ROAD, sm.SIDEWALK),
    "sky": (sm.SKY,),
}
REAL_PREFIX = "camvid_"


def world_of(clip: Path) -> str:
    return "real" if clip.name.startswith(REAL_PREFIX) else "rendered"


def count_clip(path: Path, frames: tuple[int, ...], label: str) -> dict[str, Any]:
    """Pixel counts of one clip: positives in V per group, pixels in V per group, frames with any positive
    per group, frames read."""
    seq = SequenceFolder(path)
    labels = seq.labels(label)
    pos = dict.fromkeys(GROUPS, 0)
    inv = dict.fromkeys(GROUPS, 0)
    with_any = dict.fromkeys(GROUPS, 0)
    total_pos = n = 0
    for f in frames:
        sem = cv2.imread(str(seq.semantic(f)), cv2.IMREAD_UNCHANGED)
        if sem is None:
            continue
        bs = read_mask(labels.blindspot(f))
        v = read_mask(labels.visibility(f))
        if bs.shape != sem.shape or v.shape != sem.shape:
            bs = cv2.resize(bs.astype(np.uint8), sem.shape[::-1], interpolation=cv2.INTER_NEAREST) > 0
            v = cv2.resize(v.astype(np.uint8), sem.shape[::-1], interpolation=cv2.INTER_NEAREST) > 0
        p = bs & v
        total_pos += int(p.sum())
        n += 1
        for g, ids in GROUPS.items():
            cls = np.isin(sem, ids)
            k = int((p & cls).sum())
            pos[g] += k
            inv[g] += int((v & cls).sum())
            with_any[g] += k > 0
    return {"pos": pos, "in_v": inv, "frames_with": with_any, "positives": total_pos, "frames": n}


def measure(args: argparse.Namespace, _parser: argparse.ArgumentParser) -> Report | None:
    data = Path(args.data).expanduser()
    if not data.is_dir():
        print(f"bench_label_classes: no data folder {data}: nothing to measure")
        return None
    try:
        clips = find_clips(data, args.label)
    except ValueError as e:
        raise RefusedError(str(e)) from None
    worlds: dict[str, dict[str, Any]] = {}
    for i, c in enumerate(clips, 1):
        w = worlds.setdefault(world_of(c.path), {"clips": 0, "frames": 0, "positives": 0,
                                                  "pos": dict.fromkeys(GROUPS, 0), "in_v": dict.fromkeys(GROUPS, 0),
                                                  "frames_with": dict.fromkeys(GROUPS, 0)})
        got = count_clip(c.path, c.frames, args.label)
        w["clips"] += 1
        w["frames"] += got["frames"]
        w["positives"] += got["positives"]
        for key in ("pos", "in_v", "frames_with"):
            for g in GROUPS:
                w[key][g] += got[key][g]
        print(f"label classes: {i}/{len(clips)} clips", flush=True)
    md = ["# What the labels teach, per class", "",
          f"T-frame labels `{args.label}` of `{data}`, each labelled frame at its clip's own size. A blind spot "
          "lies on the pixels of what hides the road, so a positive pixel's class is the occluder it teaches.", ""]
    for name, w in worlds.items():
        md += [f"## {name}: {w['clips']} clips, {w['frames']:,} labelled frames, "
               f"{w['positives']:,} positive pixels in V", "",
               "| occluder | share of positives | positives per frame | frames with any "
               "| its pixels in V taught positive |",
               "|---|---|---|---|---|"]
        for g in GROUPS:
            share = w["pos"][g] / max(w["positives"], 1)
            rate = w["pos"][g] / max(w["in_v"][g], 1)
            md.append(f"| {g} | {100 * share:.2f} % | {w['pos'][g] / max(w['frames'], 1):,.0f} | "
                      f"{100 * w['frames_with'][g] / max(w['frames'], 1):.1f} % | {100 * rate:.2f} % |")
        md.append("")
    return Report({"machine": machine(), "data": str(data), "label": args.label, "worlds": worlds}, md)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="bench_label_classes", description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default="~/.cache/bsn-edge/campaign/data", help="a folder of labelled clips")
    p.add_argument("--label", default="T5s", help="the labels' name (labels/NAME in each clip)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="label_classes")
    return run(measure, p, argv)


if __name__ == "__main__":
    raise SystemExit(main())
