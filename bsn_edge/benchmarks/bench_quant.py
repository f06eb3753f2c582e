"""int8 against fp32: accuracy against labels, agreement, and speed of the fused model.

    python -m bsn_edge.benchmarks.bench_quant --run RUN --data TEST_CLIPS --calib CALIB --out benchmarks/results

Accuracy: IoU, recall and precision inside V of both models against the T-frame labels of the
held-out clips, at the run's threshold, and their pixel agreement. Speed: median latency of the
fused model at 256x512 in onnxruntime with 2 intra-op threads, over >= 50 runs after warm-up,
all in one run of this script, for each activation/weight type pair.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.data import find_clips
from bsn_edge.export import QuantConfig, quantize, to_onnx
from bsn_edge.export.calib_frames import load_frames
from bsn_edge.metrics import Counts
from bsn_edge.modelfile.read import session
from bsn_edge.sequence import read_mask
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.frames import read_rgb
from bsn_edge.train.run import Run

from .common import summary, time_calls
from .runner import RefusedError, Report, run

BAR_IOU_DROP = 0.01
BAR_SPEEDUP, BAR_FPS, GOAL_FPS = 2.5, 60.0, 100.0


def latency(path: Path, frame: np.ndarray, runs: int, exact_x64: bool = True) -> float:
    """Median seconds per run of the model at ``path`` on ``frame``, after warm-up (``exact_x64``: see
    :func:`bsn_edge.modelfile.read.session`)."""
    s = session(path, threads=2, exact_x64=exact_x64)
    return summary(time_calls(lambda _: s.run(None, {"frame": frame}), runs, warmup=10))["median_ms"] / 1e3


BLOCKS = (("stem", "/stem/"), ("encoder", "/encoder/"), ("decoder", "/decoder/"),
          ("heads and upsampling", ("/head/", "/upsample", "/to_frame", "/Sigmoid", "/Exp", "/depth_net/")))


def block_of(node: str) -> str:
    """Which part of the fused model an onnxruntime profile entry belongs to (by its name)."""
    for block, keys in BLOCKS:
        if any(k in node for k in ((keys,) if isinstance(keys, str) else keys)):
            return block
    return "input and layout"


def kernel_times(path: Path, frame: np.ndarray, runs: int) -> list[tuple[str, str, float]]:
    """onnxruntime's profile of ``runs`` runs: ``(node entry name, operator, milliseconds per
    run)`` for every kernel (the profiler adds its own overhead: read shares and ratios)."""
    with tempfile.TemporaryDirectory() as tmp:
        s = session(path, threads=2, profile_prefix=str(Path(tmp) / "prof"))
        for _ in range(runs):
            s.run(None, {"frame": frame})
        events = json.loads(Path(s.end_profiling()).read_text())
    return [(e["name"], e.get("args", {}).get("op_name", "?"), e["dur"] / 1e3 / runs) for e in events
            if e.get("cat") == "Node" and e["name"].endswith("_kernel_time")]


def profile_blocks(path: Path, frame: np.ndarray, runs: int) -> dict[str, float]:
    """Milliseconds per run spent in each block, from onnxruntime's profiler (which adds its own
    overhead, so only the shares and the fp32/int8 ratios per block are meaningful)."""
    ms: dict[str, float] = {}
    for name, _, t in kernel_times(path, frame, runs):
        b = block_of(name)
        ms[b] = ms.get(b, 0.0) + t
    return ms


def accuracy(paths: dict[str, Path], clips, size, threshold: float, label: str) -> dict:
    sess = {k: session(p) for k, p in paths.items()}
    counts = {k: Counts() for k in paths}
    agree = []
    h, w = size
    for clip in clips:
        for f in clip.frames:
            frame = cv2.resize(read_rgb(clip.path, f), (w, h), interpolation=cv2.INTER_AREA)[None]
            lab = SequenceFolder(clip.path).labels(label)
            y = cv2.resize(read_mask(lab.blindspot(f)).astype(np.uint8), (w, h),
                           interpolation=cv2.INTER_NEAREST) > 0
            v = cv2.resize(read_mask(lab.visibility(f)).astype(np.uint8), (w, h),
                           interpolation=cv2.INTER_NEAREST) > 0
            masks = {k: s.run(None, {"frame": frame})[0][0, 0] >= threshold for k, s in sess.items()}
            for k, m in masks.items():
                counts[k].add(m, y, v)
            agree.append(float((masks["fp32"] == masks["int8"]).mean()))
    return {"metrics": {k: c.metrics() for k, c in counts.items()}, "pixel_agreement": float(np.mean(agree))}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True)
    p.add_argument("--data", required=True, help="held-out labelled clips")
    p.add_argument("--calib", required=True, help="calibration frames (training clips)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--runs", type=int, default=60)
    p.add_argument("--name", default="quant", help="the report's name in --out")
    return p


def _variants(fp32: Path, t_fp32: float, frames, frame, runs: int,
              tmp: Path) -> tuple[list[dict[str, Any]], dict[tuple, Path]]:
    """Each int8 variant of ``fp32`` (activations, weights, per channel) quantized and timed against its
    ``t_fp32`` seconds."""
    rows, variants = [], {}
    for acts, wts, per_channel in (("uint8", "int8", True), ("uint8", "int8", False), ("int8", "int8", True)):
        q = tmp / f"int8_{acts}_{wts}_{per_channel}.onnx"
        quantize(fp32, q, frames, QuantConfig(activations=acts, weights=wts, per_channel=per_channel))
        variants[(acts, wts, per_channel)] = q
        t = latency(q, frame, runs)
        rows.append({"activations": acts, "weights": wts, "per_channel": per_channel, "median_ms": 1e3 * t,
                     "fps": 1 / t, "speedup": t_fp32 / t})
    return rows, variants


def _markdown(res: dict[str, Any], card, n_clips: int) -> list[str]:
    m, rows, best, size = res, res["speed"], res["int8"], res["size"]
    md = ["# int8 quantization: accuracy and speed", "",
          f"Model `{card.variant}` at {size[0]}x{size[1]}, threshold {res['threshold']:.2f}, {n_clips} held-out "
          "clips, inside V.", "",
          "| model | IoU | recall | precision | ms | frames/s |", "|---|---|---|---|---|---|",
          f"| fp32 | {m['fp32']['iou']:.4f} | {m['fp32']['recall']:.4f} | {m['fp32']['precision']:.4f} | "
          f"{m['fp32']['median_ms']:.1f} | {m['fp32']['fps']:.1f} |",
          f"| int8 (uint8 act., int8 weights) | {m['int8']['iou']:.4f} | {m['int8']['recall']:.4f} | "
          f"{m['int8']['precision']:.4f} | {best['median_ms']:.1f} | {best['fps']:.1f} |", "",
          f"Pixel agreement {100 * res['pixel_agreement']:.2f} %, IoU drop {res['iou_drop']:+.4f} "
          f"(bar <= {BAR_IOU_DROP}).", "",
          "| activations | weights | ms | frames/s | speed-up over fp32 |", "|---|---|---|---|---|"]
    md += [f"| {r['activations']} | {r['weights']} {'per-channel' if r['per_channel'] else 'per-tensor'} | "
           f"{r['median_ms']:.2f} | {r['fps']:.1f} | {r['speedup']:.2f}x |" for r in rows]
    md += ["", "Where the time goes (onnxruntime's profiler, which adds overhead: compare shares and ratios):", "",
           "| block | fp32 ms | int8 ms | int8 speed-up |", "|---|---|---|---|"]
    md += [f"| {r['block']} | {r['fp32']:.2f} | {r['int8']:.2f} | {r['fp32'] / max(r['int8'], 1e-9):.2f}x |"
           for r in res["blocks_ms_profiled"]]
    md += ["", f"Bars: int8 >= {BAR_SPEEDUP}x fp32 ({'passes' if res['passes']['speedup'] else 'FAILS'}), "
           f">= {BAR_FPS:g} frames/s ({'passes' if res['passes']['fps'] else 'FAILS'}), IoU drop <= {BAR_IOU_DROP} "
           f"({'passes' if res['passes']['iou_drop'] else 'FAILS'})."]
    return md


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    trained = Run(args.run)
    model, card = trained.load_model()
    info = trained.info()
    size = (256, 512)
    card = card.at_size(*size)
    label = info.get("label", "T5s")
    seen = set(info.get("train_clips", [])) | set(info.get("val_clips", []))
    clips = [c for c in find_clips(args.data, label) if c.path.name not in seen]
    frames = load_frames(args.calib, size, 64)
    threshold = card.threshold
    if threshold is None:
        raise RefusedError(f"{args.run}: its card has no decision threshold (its training chose none)")
    with tempfile.TemporaryDirectory() as tmp:
        fp32 = Path(tmp) / "fp32.onnx"
        to_onnx(model, fp32, card)
        frame = frames[:1]
        t_fp32 = latency(fp32, frame, args.runs)
        rows, variants = _variants(fp32, t_fp32, frames, frame, args.runs, Path(tmp))
        default = variants[("uint8", "int8", True)]
        prof = {k: profile_blocks(q, frame, args.runs) for k, q in (("fp32", fp32), ("int8", default))}
        acc = accuracy({"fp32": fp32, "int8": default}, clips, size, threshold, label)
    m = acc["metrics"]
    drop = m["fp32"]["iou"] - m["int8"]["iou"]
    best = rows[0]
    res = {"model": card.variant, "threshold": threshold, "size": list(size),
           "test_clips": [c.path.name for c in clips],
           "fp32": {**m["fp32"], "median_ms": 1e3 * t_fp32, "fps": 1 / t_fp32}, "int8": {**m["int8"], **best},
           "pixel_agreement": acc["pixel_agreement"], "iou_drop": drop, "speed": rows,
           "blocks_ms_profiled": [{"block": b, "fp32": prof["fp32"].get(b, 0.0), "int8": prof["int8"].get(b, 0.0)}
                                  for b in [*(b for b, _ in BLOCKS), "input and layout"]],
           "bars": {"iou_drop_max": BAR_IOU_DROP, "speedup_min": BAR_SPEEDUP, "fps_min": BAR_FPS, "fps_goal": GOAL_FPS},
           "passes": {"iou_drop": drop <= BAR_IOU_DROP, "speedup": best["speedup"] >= BAR_SPEEDUP,
                      "fps": best["fps"] >= BAR_FPS}}
    md = _markdown(res, card, len(clips))
    return Report(res, md, md)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
