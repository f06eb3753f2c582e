"""``bsn-export``: a trained run -> the sealed, fused ONNX model the runtime reads (fp32, or int8)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from bsn_edge.card import DigestVersion, ModelCard
from bsn_edge.cli.common import fail, glue_values, parse_size
from bsn_edge.modelfile.quant_names import METHOD_NAMES, TYPE_NAMES
from bsn_edge.modelfile.selftest import SelfTestError
from bsn_edge.modelfile.trust import user_trust_dir

# torch, onnx and onnxruntime's quantization tools are imported where they work, not for --help

PROG = "bsn-export"
INT8_COUNT = 64


def _sealed_model_options(p: argparse.ArgumentParser) -> None:
    """The options that work on a sealed model instead of a run: reseal (at a new threshold), integer input."""
    p.add_argument("--reseal", metavar="MODEL.onnx",
                   help="instead of exporting: seal a model exported before models were sealed, or before their card "
                        "digest was canonical (writes its card "
                        "with the graph's sha256 and a self-test answer to --out), signed with --sign KEY.pem, "
                        "which it needs: a resealed model is vouched for by whoever resealed it. Only for a file "
                        "you trust: sealing cannot tell whether it was damaged before")
    p.add_argument("--threshold", type=float, metavar="P",
                   help="with --reseal: the card's decision threshold becomes P (a probability in (0, 1)); the graph "
                        "stays as it is, bit for bit. Needs --threshold-from")
    p.add_argument("--threshold-from", metavar="TEXT",
                   help="with --threshold: where P was chosen (the card's training record keeps it)")
    p.add_argument("--integer-input", metavar="MODEL.onnx",
                   help="instead of exporting: rewrite an int8 model exported before the integer input so its frame "
                        "is normalised by an exact integer convolution on the uint8 frame (no float frame), resealed "
                        "to --out; written only if its outputs equal the original's to the bit")


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
    p.add_argument("--out", help="output .onnx path")
    p.add_argument("--size", type=parse_size, default=None, metavar="HxW",
                   help="input size (default: the size the run was trained at)")
    p.add_argument("--int8", action="store_true", help="quantize to int8 (needs --int8-frames)")
    p.add_argument("--int8-frames", metavar="DIR_OR_VIDEO",
                   help="the frames int8's activation ranges are calibrated on: a folder of images, a sequence "
                        "folder, a folder of sequence folders (shared evenly, each warped by its own camera) or a "
                        "video (not a camera file: that is bsn-run's --calib)")
    p.add_argument("--int8-count", type=int, default=None, metavar="N",
                   help=f"how many of those frames, spread over them (default {INT8_COUNT})")
    # the names before 0.2.0, kept one release: --calib meant a camera file everywhere else
    p.add_argument("--calib", dest="old_frames", help=argparse.SUPPRESS)
    p.add_argument("--calib-frames", dest="old_count", type=int, help=argparse.SUPPRESS)
    p.add_argument("--method", choices=METHOD_NAMES, default="minmax", help="calibration method (default minmax)")
    p.add_argument("--activations", choices=TYPE_NAMES, default="uint8", help="activation type (default uint8)")
    p.add_argument("--weights", choices=TYPE_NAMES, default="int8", help="weight type (default int8)")
    p.add_argument("--per-tensor", action="store_true", help="per-tensor weights instead of per-channel")
    p.add_argument("--weight-bits", type=int, choices=(7, 8), default=7,
                   help="7 (default): weights in [-64, 63], exact at full speed on every x86 CPU; 8: the whole "
                        "int8 range, a little finer, but on x86 CPUs without VNNI (most AVX2 ones) the runtime "
                        "must then run slower exact kernels")
    p.add_argument("--reduce-range", dest="weight_bits", action="store_const", const=7,
                   help=argparse.SUPPRESS)   # the earlier spelling of --weight-bits 7
    p.add_argument("--quantize-heads", action="store_true",
                   help="quantize the output heads too (by default they stay float)")
    _sealed_model_options(p)
    p.add_argument("--no-prune", action="store_true",
                   help="keep every convolution channel (by default the channels nothing reads, whose every "
                        "reader multiplies them by exactly zero, are taken out of the graph: the same outputs "
                        "for fewer multiply-accumulates)")
    p.add_argument("--ship-run", metavar="DIR",
                   help="also write the run itself beside the model: D and B weights and the teacher in fp16, "
                        "each with its sha256, the card, config and history (no optimizer state), so users can "
                        "fine-tune (bsn-train --set train.init=DIR), adapt (bsn-adapt --run DIR), evaluate and "
                        "export it without a training run of their own")
    p.add_argument("--sign", metavar="KEY.pem",
                   help="sign the sealed model with this Ed25519 private key (bsn-run --trust KEY.pem.pub then "
                        "refuses any model this key did not sign)")
    p.add_argument("--new-key", metavar="KEY.pem",
                   help="write a new Ed25519 key pair (KEY.pem, readable by you only, and KEY.pem.pub to hand out) "
                        "and exit")
    p.add_argument("--force", action="store_true", help="overwrite --out (and --ship-run) if it exists")
    return p


def signed(model: Path, key: str | None) -> int:
    """Sign ``model`` with ``key`` when one is given, else say plainly that it is unsigned; 0, or 2 with a
    message."""
    if not key:
        print(f"note: {model} is unsigned: bsn-run refuses it unless it is run with --allow-unsigned. Sign it with "
              "--sign KEY.pem (bsn-export --new-key KEY.pem makes a key pair; bsn-run trusts KEY.pem.pub given with "
              f"--trust or put in {user_trust_dir()})")
        return 0
    from bsn_edge.export.signing import sign
    try:
        kid = sign(model, key)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    print(f"signed {model} with key {kid}")
    return 0


def rethresholded(card: ModelCard, threshold: float | None, chosen_on: str | None) -> ModelCard:
    """``card`` deciding at ``threshold`` (chosen on ``chosen_on``, which its training record keeps); as
    it is when ``threshold`` is None."""
    if threshold is None:
        return card
    if card.training is None:
        raise ValueError("the model's card has no training record to say where its new threshold was chosen")
    if chosen_on is None or not chosen_on.strip():
        raise ValueError("a new threshold needs where it was chosen: a card without it says its run's validation "
                         "clips chose it")
    return card.replace(threshold=threshold, training=dataclasses.replace(card.training, threshold_from=chosen_on))


def reseal(src: Path, out: Path, threshold: float | None = None, chosen_on: str | None = None) -> int:
    from bsn_edge.export.seal import read_card, seal

    try:
        card = rethresholded(read_card(src, (DigestVersion.V2, DigestVersion.V1)), threshold, chosen_on)
        sealed = seal(src, card.replace(graph_sha256="", self_test=None), out)
    except (FileNotFoundError, ValueError, SelfTestError) as e:
        return fail(PROG, f"{src}: {e}" if isinstance(e, SelfTestError) else str(e))
    except Exception as e:          # onnxruntime refusing the graph
        return fail(PROG, f"{src}: cannot be sealed: {type(e).__name__}: {e}")
    print(f"wrote {out}: {sealed.variant} {sealed.input_size[0]}x{sealed.input_size[1]}, threshold "
          f"{sealed.threshold}, graph sha256 {sealed.graph_sha256[:16]}..., self-test recorded")
    return 0


def _old_names(args: argparse.Namespace) -> None:
    """The spellings before 0.2.0, still taken this release, each with a warning."""
    for old, new, value, field in (("--calib", "--int8-frames", args.old_frames, "int8_frames"),
                                   ("--calib-frames", "--int8-count", args.old_count, "int8_count")):
        if value is None:
            continue
        print(f"{PROG}: warning: {old} is now {new} ({old} means a camera file in bsn-run and bsn-calibrate); "
              "the old name goes in the next release", file=sys.stderr)
        if getattr(args, field) is None:
            setattr(args, field, value)
    if args.int8_count is None:
        args.int8_count = INT8_COUNT


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(glue_values(argv))
    if args.new_key:
        return _new_key(args.new_key, args.force)
    if not args.out:
        return fail(PROG, "--out MODEL.onnx is required (or --new-key KEY.pem)")
    out = Path(args.out)
    if args.sign:
        from bsn_edge.export.signing import load_private_key
        try:
            load_private_key(args.sign)     # a bad key is refused before any work
        except (FileNotFoundError, ValueError) as e:
            return fail(PROG, str(e))
    if out.exists() and not args.force:
        return fail(PROG, f"{out} exists; pass --force to overwrite it")
    blank_from = args.threshold_from is not None and not args.threshold_from.strip()
    if (args.threshold is None) != (args.threshold_from is None) or blank_from:
        return fail(PROG, "--threshold and --threshold-from go together: a new threshold says where it was chosen "
                          "(--threshold-from may not be blank)")
    if args.threshold is not None and not args.reseal:
        return fail(PROG, "--threshold re-decides a sealed model: give it with --reseal MODEL.onnx (an export "
                          "takes its run's threshold)")
    if args.threshold is not None and not 0 < args.threshold < 1:
        return fail(PROG, f"--threshold must be a probability in (0, 1), got {args.threshold}")
    if args.reseal:
        if not args.sign:
            return fail(PROG, "--reseal needs --sign KEY.pem: a resealed model is vouched for only by whoever "
                              "resealed it, and bsn-run runs only models signed by a key it trusts (bsn-export "
                              "--new-key KEY.pem makes a key pair)")
        return reseal(Path(args.reseal), out, args.threshold, args.threshold_from) or signed(out, args.sign)
    if args.integer_input:
        return _integer_input(args.integer_input, out) or signed(out, args.sign)
    if not args.checkpoint:
        return fail(PROG, "--checkpoint RUN is required (or --reseal / --integer-input MODEL.onnx)")
    _old_names(args)
    if args.int8 and not args.int8_frames:
        return fail(PROG, "--int8 needs --int8-frames DIR_OR_VIDEO (frames to calibrate activation ranges on)")
    from bsn_edge.train.run import Run

    if args.ship_run and Run(args.ship_run).exists() and not args.force:
        return fail(PROG, f"--ship-run {args.ship_run} already holds a run; pass --force to replace it")
    return _export(args, out) or signed(out, args.sign) or _ship(args)


def _new_key(path: str, force: bool) -> int:
    from bsn_edge.export.signing import new_key
    try:
        priv, pub, kid = new_key(path, force)
    except (FileExistsError, OSError) as e:
        return fail(PROG, str(e))
    print(f"wrote the private key {priv} (keep it: it signs your models) and the public key {pub} "
          f"(key {kid}; give it to bsn-run --trust, or put it in {user_trust_dir()})")
    return 0


def _integer_input(src: str, out: Path) -> int:
    from bsn_edge.export.pipeline import upgrade_integer_input
    try:
        summary = upgrade_integer_input(src, out)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    replaced = summary["quantization"]["integer_input"]["replaced"]
    print(f"wrote {out}: the frame's preparation ({', '.join(replaced)}) as one integer convolution; "
          "outputs equal to the original's to the bit; resealed")
    return 0


def _export(args: argparse.Namespace, out: Path) -> int:
    from bsn_edge.export.pipeline import export_run
    from bsn_edge.export.quantize import QuantConfig

    try:
        qcfg = QuantConfig(args.method, args.activations, args.weights, not args.per_tensor, not args.quantize_heads,
                           args.weight_bits == 7)
        summary = export_run(args.checkpoint, out, args.size, args.int8, args.int8_frames, args.int8_count, qcfg,
                             prune_dead=not args.no_prune)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB); fp32 parity: max |dp| "
          f"{summary['parity_fp32']['max_abs_prob']:.1e}; sealed (graph sha256 "
          f"{summary['card']['graph_sha256'][:16]}...)")
    if args.int8:
        c = summary["int8_vs_fp32"]
        print(f"int8 vs fp32 on {c['frames']} frames: max |dp| {c['max_abs_prob']:.3f}, mask agreement "
              f"{100 * c['mask_agreement']:.2f} %, depth median rel. diff {100 * c['depth_median_rel']:.2f} %; "
              f"{len(summary['quantization']['float_nodes'])} nodes kept float (the output heads and what of the "
              "frame's preparation is not integer; reasons in the summary)")
    return 0


def _ship(args: argparse.Namespace) -> int:
    if not args.ship_run:
        return 0
    from bsn_edge.train.run import Run

    try:
        from bsn_edge.train.ship import ship_run

        shipped = ship_run(Run(args.checkpoint), args.ship_run, force=args.force)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    size = sum(f.stat().st_size for f in shipped.path.rglob("*") if f.is_file())
    print(f"wrote the run to {shipped.path} ({size / 1e6:.1f} MB, fp16 weights and teacher)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
