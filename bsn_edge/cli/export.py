"""``bsn-export``: a trained run -> the sealed, fused ONNX model the runtime reads (fp32, or int8)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from bsn_edge.cli.common import fail, parse_size
from bsn_edge.export.calib_frames import load_frames
from bsn_edge.export.fused import check_parity, to_onnx
from bsn_edge.export.quantize import METHODS, TYPES, QuantConfig, quantize
from bsn_edge.export.seal import read_card, seal
from bsn_edge.runtime.model_file import session
from bsn_edge.sequence.images import atomic_write_bytes
from bsn_edge.train.run import Run

PROG = "bsn-export"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Export a trained run to one ONNX graph running D and B together: uint8 BGR frame "
                    "[1, H, W, 3] in, 'blindspot' probabilities and 'depth' metres out, normalisation inside, "
                    "the model card (variant, size, threshold, model camera, depth range, quantization, "
                    "digests) in its metadata, sealed with the sha256 of the graph and a self-test answer "
                    "that bsn-run checks before it starts. Checked with onnx.checker and against torch in "
                    "onnxruntime. With --int8, statically quantized (QDQ) on calibration frames.")
    p.add_argument("--checkpoint", metavar="RUN", help="training run folder (bsn-train --out)")
    p.add_argument("--out", required=True, help="output .onnx path")
    p.add_argument("--size", type=parse_size, default=None, metavar="HxW",
                   help="input size (default: the size the run was trained at)")
    p.add_argument("--int8", action="store_true", help="quantize to int8 (needs --calib)")
    p.add_argument("--calib", help="calibration frames: a folder of images (or sequence folders) or a video")
    p.add_argument("--calib-frames", type=int, default=64, help="calibration frames to use (default 64)")
    p.add_argument("--method", choices=sorted(METHODS), default="minmax", help="calibration method (default minmax)")
    p.add_argument("--activations", choices=sorted(TYPES), default="uint8", help="activation type (default uint8)")
    p.add_argument("--weights", choices=sorted(TYPES), default="int8", help="weight type (default int8)")
    p.add_argument("--per-tensor", action="store_true", help="per-tensor weights instead of per-channel")
    p.add_argument("--quantize-heads", action="store_true",
                   help="quantize the output heads too (by default they stay float)")
    p.add_argument("--reseal", metavar="MODEL.onnx",
                   help="instead of exporting: seal a model exported before models were sealed (writes its card "
                        "with the graph's sha256 and a self-test answer to --out). Only for a file you trust: "
                        "sealing cannot tell whether it was damaged before")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    return p


def reseal(src: Path, out: Path) -> int:
    try:
        card = read_card(src)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    sealed = seal(src, card.replace(graph_sha256="", self_test=None), out)
    print(f"wrote {out}: {sealed.variant} {sealed.input_size[0]}x{sealed.input_size[1]}, graph sha256 "
          f"{sealed.graph_sha256[:16]}..., self-test recorded")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    if out.exists() and not args.force:
        return fail(PROG, f"{out} exists; pass --force to overwrite it")
    if args.reseal:
        return reseal(Path(args.reseal), out)
    if not args.checkpoint:
        return fail(PROG, "--checkpoint RUN is required (or --reseal MODEL.onnx)")
    if args.int8 and not args.calib:
        return fail(PROG, "--int8 needs --calib DIR_OR_VIDEO (frames to calibrate activation ranges on)")
    if args.calib_frames < 1:
        return fail(PROG, f"--calib-frames must be >= 1, got {args.calib_frames}")
    try:
        model, card = Run(args.checkpoint).load_model()
        if card.threshold is None:
            raise ValueError(f"{args.checkpoint}: the run has no decision threshold yet (training did not finish)")
        h, w = args.size or card.input_size
        card = card.at_size(h, w)
        qcfg = QuantConfig(args.method, args.activations, args.weights, not args.per_tensor, not args.quantize_heads)
        frames = load_frames(args.calib, (h, w), args.calib_frames, card=card) if args.calib else None
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    out.parent.mkdir(parents=True, exist_ok=True)
    check_frames = list(frames[:4]) if frames is not None else \
        [np.random.default_rng(i).integers(0, 256, (h, w, 3), dtype=np.uint8) for i in range(2)]
    summary: dict = {"checkpoint": str(args.checkpoint), "size": [h, w]}
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        fp32 = Path(tmp) / "fp32.onnx"
        print(f"exporting {card.variant} at {h}x{w} ...", file=sys.stderr)
        sealed = to_onnx(model, fp32, card)
        try:
            summary["parity_fp32"] = check_parity(model, fp32, check_frames)
        except ValueError as e:
            return fail(PROG, str(e), 1)
        summary["fp32_bytes"] = fp32.stat().st_size
        final = fp32
        if args.int8:
            print(f"quantizing on {len(frames)} calibration frames ({qcfg.scheme()}) ...", file=sys.stderr)
            q = Path(tmp) / "int8.onnx"
            info = quantize(fp32, q, frames, qcfg)
            sealed = info.pop("card")
            summary.update(int8_bytes=q.stat().st_size, quantization=info,
                           int8_vs_fp32=compare(fp32, q, frames, sealed.threshold))
            final = q
        final.replace(out)
    card_record = sealed.to_dict()
    card_record["self_test"] = dataclasses.asdict(sealed.self_test) | {"prob": "...", "depth": "..."}
    summary["card"] = card_record
    atomic_write_bytes(out.with_suffix(".json"), (json.dumps(summary, indent=1) + "\n").encode())
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB); fp32 parity: max |dp| "
          f"{summary['parity_fp32']['max_abs_prob']:.1e}; sealed (graph sha256 {sealed.graph_sha256[:16]}...)")
    if args.int8:
        c = summary["int8_vs_fp32"]
        print(f"int8 vs fp32 on {c['frames']} frames: max |dp| {c['max_abs_prob']:.3f}, mask agreement "
              f"{100 * c['mask_agreement']:.2f} %, depth median rel. diff {100 * c['depth_median_rel']:.2f} %; "
              f"{len(summary['quantization']['float_nodes'])} nodes kept float (the frame's preparation and the "
              "output heads; reasons in the summary)")
    return 0


def compare(fp32: Path, int8: Path, frames: np.ndarray, threshold: float) -> dict[str, float]:
    """How far the int8 model strays from fp32 on ``frames``."""
    a, b = session(fp32), session(int8)
    dp, agree, rel = 0.0, [], []
    for f in frames:
        pa, da = a.run(None, {"frame": f[None]})
        pb, db = b.run(None, {"frame": f[None]})
        dp = max(dp, float(np.abs(pa - pb).max()))
        agree.append(float(((pa >= threshold) == (pb >= threshold)).mean()))
        rel.append(float(np.median(np.abs(da - db) / np.maximum(da, 1e-3))))
    return {"frames": len(frames), "max_abs_prob": dp, "mask_agreement": float(np.mean(agree)),
            "depth_median_rel": float(np.median(rel))}


if __name__ == "__main__":
    raise SystemExit(main())
