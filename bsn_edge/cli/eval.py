"""``bsn-eval``: IoU, recall and precision inside V of a trained run and the baselines; BSN's average
precision."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from bsn_edge.cli.common import fail, glue_values, parse_size

PROG = "bsn-eval"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Evaluate a run on labelled clips: IoU, recall and precision inside the visibility "
                    "mask V, overall and per clip, for BlindSpotNet (at the threshold chosen on validation) "
                    "and the baselines Traversable, Detection-2D and Detection-3D. For BlindSpotNet also two "
                    "scores that need no threshold: the average precision of its probabilities, and the best "
                    "IoU any threshold would give on these clips (an upper bound). Writes REPORT.json and an "
                    "image grid REPORT.png beside it.")
    p.add_argument("--run", required=True, help="training run folder (bsn-train --out)")
    p.add_argument("--data", required=True, help="folder of labelled sequence folders")
    p.add_argument("--out", required=True, help="report JSON path")
    p.add_argument("--clips", choices=("held-out", "all"), default="held-out",
                   help="held-out (default): skip clips the run trained or validated on; all: every clip")
    p.add_argument("--styles", nargs="*", default=None, help="only clips of these styles")
    p.add_argument("--size", type=parse_size, default=None, metavar="HxW",
                   help="evaluation size (default: the run's training size)")
    p.add_argument("--no-baselines", action="store_true", help="evaluate BlindSpotNet only")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(glue_values(argv))
    # evaluation's modules (torch) after the command line: --help needs none of them
    from bsn_edge.data import find_clips
    from bsn_edge.evaluate.evaluator import evaluate, grid_image
    from bsn_edge.sequence import write_image
    from bsn_edge.sequence.images import atomic_write_bytes
    from bsn_edge.train.run import Run

    run = Run(args.run)
    try:
        model, card = run.load_model()
        info, cfg = run.info(), run.config()
        label = info.get("label", "T5s")
        clips = find_clips(args.data, label)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    if args.clips == "held-out":
        seen = set(info.get("train_clips", [])) | set(info.get("val_clips", []))
        clips = [c for c in clips if c.path.name not in seen]
    if args.styles:
        clips = [c for c in clips if c.style in args.styles]
    if not clips:
        if args.clips == "held-out":
            return fail(PROG, f"no held-out clips in {args.data}: the run trained or validated on every labelled "
                              f"clip there (styles: {args.styles or 'any'}). Label clips it never saw into another "
                              "folder and pass that as --data, or pass --clips all to score the training clips too "
                              "(an optimistic figure)")
        return fail(PROG, f"no labelled clips of styles {args.styles} in {args.data}")
    size = tuple(args.size or card.input_size)
    teacher = None if args.no_baselines else run.load_teacher()
    res = evaluate(model, card, clips, size, label, teacher,
                   teacher_scale=float(cfg.get("teacher", {}).get("scale", 0.5)), baselines=not args.no_baselines)
    rows = res.pop("grid_rows")
    report = {"run": str(run.path), "model": card.variant, "size": list(size),
              "clips": [c.path.name for c in clips], **res}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out, (json.dumps(report, indent=1) + "\n").encode())
    if rows:
        write_image(out.with_suffix(".png"), grid_image(rows, res["methods"]))
    print(f"{'method':<14} {'IoU':>6} {'recall':>7} {'precision':>9}   "
          f"({len(clips)} clips, {size[0]}x{size[1]})")
    for m, r in report["overall"].items():
        print(f"{m:<14} {r['iou']:>6.3f} {r['recall']:>7.3f} {r['precision']:>9.3f}")
    bsn = report["overall"].get("BSN", {})
    if bsn.get("ap") is not None:
        print(f"BSN without its threshold: average precision {bsn['ap']:.3f}; the best threshold on these clips, "
              f"{bsn['best_threshold']:.2f}, would give IoU {bsn['best_iou']:.3f} (an upper bound: chosen on the "
              f"clips it scores; the run's own is {report['threshold']:.2f})")
    if model.oracle_depth:
        print(f"B read {report['b_reads']}: these figures are not what a car would see")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
