"""Held-out synthetic IoU of exported models, side by side, on clips whose cameras no model trained with.

    python -m bsn_edge.benchmarks.bench_cameras --set "varied cameras=DIR:clip,clip" --set "fixed camera=DIR2" \\
        --model A.onnx --model B.onnx --out benchmarks/results

Each model runs as ``bsn-run`` runs it: every clip warped into the model's own camera (its card),
uint8 frames into the int8 graph, its own threshold. IoU, recall and precision inside V against the
T-frame labels (warped the same way), pooled over every labelled frame of the set's clips; the
depth's AbsRel on vehicle and on road pixels, 5-10, 10-20 and 20-40 m, against the clips' exact depth;
and the road users marked as ``realboxes`` counts them on real frames (at least 15 % of an occluder's
box blind spot; boxes from the clips' own semantics and depth, ``bsn_edge/benchmarks/road_users.py``), by
kind and near (under 20 m) or all, for the model and for the labels themselves: what the T-frame
definition marks is the most a model trained on it learns to mark.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.data import BlindSpotDataset, find_clips
from bsn_edge.metrics import Counts, DepthBins
from bsn_edge.runtime.engine import Engine
from bsn_edge.semantics import ROAD, VEHICLES

from . import runner
from .bench_realboxes import MARKED_SHARE, frac, score, summary
from .common import load_engine, named
from .road_users import NEAR_M, road_users
from .runner import RefusedError, Report

DEPTH_BINS_M = ((5.0, 10.0), (10.0, 20.0), (20.0, 40.0))
DEPTH_CLASSES = {"vehicle": VEHICLES, "road": (ROAD,)}


def evaluate(engine: Engine, clips, label: str = "T5s") -> dict[str, Any]:
    """Blind-spot IoU, recall and precision inside V, and the depth's AbsRel on vehicle and road
    pixels in distance bins (``depth_abs_rel``: class -> "5-10" ... -> value)."""
    card = engine.card
    counts = Counts()
    by_clip: dict[str, Counts] = {}
    frames = 0
    pooled = {c: DepthBins(DEPTH_BINS_M) for c in DEPTH_CLASSES}
    marked: dict[str, list[dict[str, Any]]] = {"model": [], "labels": []}
    for clip in clips:
        ds = BlindSpotDataset([clip], card.input_size, label_name=label, camera=card.camera, mounting=card.mounting)
        own = by_clip.setdefault(clip.path.name, Counts())
        for k in range(len(ds)):
            item = ds.load(k)
            prob, depth = engine.infer(item["rgb"][None])
            for c in (counts, own):
                c.add(prob >= engine.threshold, item["blindspot"] > 0, item["visibility"] > 0)
            pred, true, sem = np.asarray(depth).reshape(item["depth"].shape), item["depth"], item["semantic"]
            boxes = road_users(sem, true)
            marked["model"] += score(prob >= engine.threshold, boxes)
            marked["labels"] += score(item["blindspot"] > 0, boxes)
            for kind, ids in DEPTH_CLASSES.items():
                on = np.isin(sem, ids)
                pooled[kind].add(pred[on], true[on])
            frames += 1
    depth_abs_rel = {c: pooled[c].abs_rel() for c in DEPTH_CLASSES}
    clips_out = {name: {**c.metrics(), "label_px_in_v": c.tp + c.fn} for name, c in by_clip.items()}
    return {**counts.metrics(), "frames": frames, "depth_abs_rel": depth_abs_rel, "clips": clips_out,
            "road_users": {k: summary(v) for k, v in marked.items()}}


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def parse_set(text: str) -> tuple[str, Path, list[str]]:
    name, _, rest = text.partition("=")
    folder, _, names = rest.partition(":")
    return name, Path(folder), [n for n in names.split(",") if n]


def _row(label: str, name: str, m: dict[str, Any]) -> str:
    d = m["depth_abs_rel"]
    return (f"| {label} | {name} | {m['frames']} | {m['iou']:.3f} | {m['recall']:.3f} | {m['precision']:.3f} | "
            + " / ".join(_fmt(v) for v in d["vehicle"].values()) + " | "
            + " / ".join(_fmt(v) for v in d["road"].values()) + " |")


def _users_row(label: str, name: str, m: dict[str, Any]) -> list[str]:
    if "road_users" not in m:          # a row kept from a report written before road users were counted
        return []
    rows = []
    for who in ("model", "labels"):
        s = m["road_users"][who]
        g = s["groups"]
        rows.append(f"| {label} | {name} | {who} | {frac(s['near'])} / {frac(s['all'])} | "
                    f"{frac(g['vehicles']['near'])} / {frac(g['vehicles']['all'])} | "
                    f"{frac(g['people']['near'])} / {frac(g['people']['all'])} | "
                    f"{frac(g['cyclists']['near'])} / {frac(g['cyclists']['all'])} |")
    return rows


def _clip_rows(label: str, name: str, m: dict[str, Any]) -> list[str]:
    total = sum(c["label_px_in_v"] for c in m.get("clips", {}).values()) or 1
    return [f"| {label} | {name} | {clip} | {c['label_px_in_v']:,} ({100 * c['label_px_in_v'] / total:.0f} %) | "
            f"{c['iou']:.3f} |" for clip, c in m.get("clips", {}).items()]


def kept_models(path: Path, sets: dict[str, list[str]], measured: list[str]) -> dict[str, Any]:
    """The models of an earlier report at ``path`` measured on the same ``sets`` and not measured
    again now (``--keep``); nothing from a report of other sets."""
    if not path.is_file():
        return {}
    old = json.loads(path.read_text())
    if old.get("sets") != sets:
        raise ValueError(f"{path} was measured on other sets: --keep needs the same --set arguments")
    return {k: v for k, v in old.get("models", {}).items() if k not in measured}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--set", action="append", required=True, metavar="NAME=DIR[:CLIP,CLIP]",
                   help="a named set of labelled clips: a folder, optionally only the named clips")
    p.add_argument("--model", action="append", required=True, metavar="[NAME=]MODEL.onnx[@THRESHOLD]",
                   help="a model to evaluate, named in the report by NAME (default: its file's stem), at its card's "
                        "threshold or at the one after @")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="cameras", help="the report's name in --out")
    p.add_argument("--keep", action="store_true",
                   help="keep the rows of models the existing report measured on the same sets (models whose "
                        "files are gone), first; a model named again is measured again")
    return p


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    sets = []
    for text in args.set:
        name, folder, names = parse_set(text)
        clips = [c for c in find_clips(folder) if not names or c.path.name in names]
        sets.append((name, clips))
    result: dict[str, Any] = {"sets": {n: [c.path.name for c in cs] for n, cs in sets}, "models": {}}
    try:
        labels = list(named(args.model).items())
    except ValueError as e:
        p.error(str(e))
    if args.keep:
        try:
            result["models"] = kept_models(Path(args.out) / f"{args.name}.json", result["sets"],
                                           [lb for lb, _ in labels])
        except ValueError as e:
            raise RefusedError(str(e)) from None
    for label, mp in labels:
        engine = load_engine(mp)
        result["models"][label] = {name: evaluate(engine, clips) for name, clips in sets}
    rows = [_row(label, name, m) for label, res in result["models"].items() for name, m in res.items()]
    md = "\n".join(["# Held-out synthetic IoU, every clip in the model's own camera", "",
                    "Inside V, at each model's own threshold, int8 through onnxruntime as bsn-run runs it.", "",
                    "| model | clips | frames | IoU | recall | precision | vehicle depth AbsRel 5-10 / 10-20 / 20-40 m "
                    "| road depth AbsRel |", "|---|---|---|---|---|---|---|---|", *rows, "",
                    *[f"- {n}: {', '.join(c.path.name for c in cs)}" for n, cs in sets], "",
                    "## Road users marked", "",
                    f"As `realboxes` counts real occluders: marked when at least {100 * MARKED_SHARE:.0f} % of its box "
                    "is blind spot (the model at its threshold; the labels as they are). Boxes from each frame's "
                    "semantics and depth in the model camera (`bsn_edge/benchmarks/road_users.py`); near: median depth "
                    "under "
                    f"{NEAR_M:.0f} m.", "",
                    "| model | clips | marked by | near / all | vehicles near / all | people near / all | "
                    "cyclists near / all |", "|---|---|---|---|---|---|---|",
                    *[r for label, res in result["models"].items() for name, m in res.items()
                      for r in _users_row(label, name, m)], "",
                    "## Where each set's IoU comes from", "",
                    "The IoU is pooled over a set's pixels: a clip weighs by its label pixels inside V (surfaces "
                    "nearer than the labels' L). A clip whose blind spots all lie beyond L has next to none, and its "
                    "own IoU is over a handful of pixels.", "",
                    "| model | clips | clip | label pixels in V (share of the set's) | IoU |", "|---|---|---|---|---|",
                    *[r for label, res in result["models"].items() for name, m in res.items()
                      for r in _clip_rows(label, name, m)]])
    return Report(result, [md], [md])


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
