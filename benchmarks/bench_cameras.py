"""Held-out synthetic IoU of exported models, side by side, on clips whose cameras no model trained with.

    python -m benchmarks.bench_cameras --set "varied cameras=DIR:clip,clip" --set "fixed camera=DIR2" \\
        --model A.onnx --model B.onnx --out benchmarks/results

Each model runs as ``bsn-run`` runs it: every clip warped into the model's own camera (its card),
uint8 frames into the int8 graph, its own threshold. IoU, recall and precision inside V against the
T-frame labels (warped the same way), pooled over every labelled frame of the set's clips; and the
depth's AbsRel on vehicle and on road pixels, 5-10, 10-20 and 20-40 m, against the clips' exact depth.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import write_result
from bsn_edge.data import BlindSpotDataset, find_clips
from bsn_edge.metrics import Counts, DepthBins
from bsn_edge.runtime.engine import Engine
from bsn_edge.semantics import ROAD, VEHICLES

DEPTH_BINS_M = ((5.0, 10.0), (10.0, 20.0), (20.0, 40.0))
DEPTH_CLASSES = {"vehicle": VEHICLES, "road": (ROAD,)}


def evaluate(engine: Engine, clips, label: str = "T5s") -> dict[str, Any]:
    """Blind-spot IoU, recall and precision inside V, and the depth's AbsRel on vehicle and road
    pixels in distance bins (``depth_abs_rel``: class -> "5-10" ... -> value)."""
    card = engine.card
    counts = Counts()
    frames = 0
    pooled = {c: DepthBins(DEPTH_BINS_M) for c in DEPTH_CLASSES}
    for clip in clips:
        ds = BlindSpotDataset([clip], card.input_size, label_name=label, camera=card.camera, mounting=card.mounting)
        for k in range(len(ds)):
            item = ds.load(k)
            prob, depth = engine.infer(item["rgb"][None])
            counts.add(prob >= card.threshold, item["blindspot"] > 0, item["visibility"] > 0)
            pred, true, sem = np.asarray(depth).reshape(item["depth"].shape), item["depth"], item["semantic"]
            for c, ids in DEPTH_CLASSES.items():
                on = np.isin(sem, ids)
                pooled[c].add(pred[on], true[on])
            frames += 1
    depth_abs_rel = {c: pooled[c].abs_rel() for c in DEPTH_CLASSES}
    return {**counts.metrics(), "frames": frames, "depth_abs_rel": depth_abs_rel}


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


def kept_models(path: Path, sets: dict[str, list[str]], measured: list[str]) -> dict[str, Any]:
    """The models of an earlier report at ``path`` measured on the same ``sets`` and not measured
    again now (``--keep``); nothing from a report of other sets."""
    if not path.is_file():
        return {}
    old = json.loads(path.read_text())
    if old.get("sets") != sets:
        raise ValueError(f"{path} was measured on other sets: --keep needs the same --set arguments")
    return {k: v for k, v in old.get("models", {}).items() if k not in measured}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--set", action="append", required=True, metavar="NAME=DIR[:CLIP,CLIP]",
                   help="a named set of labelled clips: a folder, optionally only the named clips")
    p.add_argument("--model", action="append", required=True, metavar="[NAME=]MODEL.onnx",
                   help="a model to evaluate, named in the report by NAME (default: its file name)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--keep", action="store_true",
                   help="keep the rows of models the existing report measured on the same sets (models whose "
                        "files are gone), first; a model named again is measured again")
    args = p.parse_args(argv)
    sets = []
    for text in args.set:
        name, folder, names = parse_set(text)
        clips = [c for c in find_clips(folder) if not names or c.path.name in names]
        sets.append((name, clips))
    result: dict[str, Any] = {"sets": {n: [c.path.name for c in cs] for n, cs in sets}, "models": {}}
    labels = [(spec.rpartition("=")[0] or Path(spec.rpartition("=")[2]).name, spec.rpartition("=")[2])
              for spec in args.model]
    if args.keep:
        try:
            result["models"] = kept_models(Path(args.out) / "cameras.json", result["sets"], [lb for lb, _ in labels])
        except ValueError as e:
            print(f"bench_cameras: {e}")
            return 2
    for label, mp in labels:
        engine = Engine(mp)
        result["models"][label] = {name: evaluate(engine, clips) for name, clips in sets}
    rows = [_row(label, name, m) for label, res in result["models"].items() for name, m in res.items()]
    md = "\n".join(["# Held-out synthetic IoU, every clip in the model's own camera", "",
                    "Inside V, at each model's own threshold, int8 through onnxruntime as bsn-run runs it.", "",
                    "| model | clips | frames | IoU | recall | precision | vehicle depth AbsRel 5-10 / 10-20 / 20-40 m "
                    "| road depth AbsRel |", "|---|---|---|---|---|---|---|---|", *rows, "",
                    *[f"- {n}: {', '.join(c.path.name for c in cs)}" for n, cs in sets]])
    write_result(args.out, "cameras", result, md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
