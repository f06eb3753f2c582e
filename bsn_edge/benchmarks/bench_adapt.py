"""bsn-adapt across styles: a model trained on one style, adapted on unlabelled clips of another.

    python -m bsn_edge.benchmarks.bench_adapt --data DATA --eval EVAL --source suburb --target urban \\
        --seeds 0 1 2 --work W --out benchmarks/results

``DATA`` and ``EVAL`` hold labelled synthetic clips of every style (bsn-synth + bsn-label: exact
depth, semantics and poses), ``EVAL`` with seeds no ``DATA`` clip has. Rows, all measured as IoU
inside V against the exact T-frame labels of the ``EVAL`` clips of the target style, each model at
its own threshold:

- before: the source-style model as trained;
- bsn-adapt: the same model adapted with bsn-adapt's own stages on the target style's ``DATA``
  clips, reading only their frames and camera files (labels from the model's depth or, where it
  does not fit, the road plane of the clip's mounting (``--label-depth``), its teacher and the
  built-in VO, with bsn-adapt's look check; threshold by agreement with those labels);
- exact labels (upper bound): the same fine-tuning, on the same clips, with their exact labels.

The source model is trained once (its seed 0); fine-tuning runs once per seed. Gap closed =
(bsn-adapt - before) / (exact - before), per seed.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.adapt.config import LABEL_DEPTHS, AdaptConfig
from bsn_edge.adapt.finetune import agreement, at_threshold
from bsn_edge.adapt.pipeline import label_clips, tune
from bsn_edge.adapt.workspace import AdaptFolder
from bsn_edge.cli.common import CHECKOUT
from bsn_edge.data.dataset import BlindSpotDataset, find_clips
from bsn_edge.train import Run, load_config
from bsn_edge.train.trainer import train

from .runner import RefusedError, Report, run


def evaluate(run: Path, clips: list, label: str) -> dict[str, float]:
    model, card = Run(run).load_model()
    ds = BlindSpotDataset(clips, card.input_size, label_name=label, camera=card.camera, mounting=card.mounting)
    if card.threshold is None:
        raise RefusedError(f"{run}: its card has no decision threshold (its training chose none)")
    return at_threshold(agreement(model, ds), card.threshold)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True)
    p.add_argument("--eval", required=True)
    p.add_argument("--source", default="suburb")
    p.add_argument("--target", default="urban")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--work", default="benchmarks/scratch/adapt")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--size", default="128,256", help="training size H,W of the source model (default 128,256)")
    p.add_argument("--train-steps", type=int, default=600)
    p.add_argument("--adapt-steps", type=int, default=300)
    p.add_argument("--label-depth", default=AdaptConfig.label_depth, choices=LABEL_DEPTHS,
                   help="depth bsn-adapt labels with (default: %(default)s)")
    p.add_argument("--name", default="adapt", help="the report's name in --out")
    return p


def _source_model(args: argparse.Namespace, src: Path, h: int, w: int) -> None:
    """The source-style model, trained into ``src`` unless it is there already."""
    if not Run(src).checkpoint_path.is_file():
        cfg = load_config(CHECKOUT / "configs" / "quick.toml",
                          [f"data.size=[{h},{w}]", f"data.train_styles=[\"{args.source}\"]", "data.test_fraction=0.0",
                           f"train.steps={args.train_steps}", "teacher.scale=1.0"])
        train(cfg, args.data, src, force=True)


def _tuned(args: argparse.Namespace, src: Path, pseudo: list, target: list, held: list,
           label: str) -> dict[str, list[dict[str, float]]]:
    """The source model before, adapted on bsn-adapt's labels and fine-tuned on the exact ones, per seed."""
    work = Path(args.work)
    rows: dict[str, list[dict[str, float]]] = {"before": [], "bsn-adapt": [], "exact labels": []}
    rows["before"].append(evaluate(src, held, label))
    for seed in args.seeds:
        cfg = AdaptConfig(seed=seed, steps=args.adapt_steps, label_depth=args.label_depth)
        tune(Run(src), pseudo, work / f"adapted_s{seed}", cfg, {}, progress=False)
        rows["bsn-adapt"].append(evaluate(work / f"adapted_s{seed}", held, label))
        tune(Run(src), target, work / f"exact_s{seed}", cfg, {}, progress=False)
        rows["exact labels"].append(evaluate(work / f"exact_s{seed}", held, label))
        print(seed, {k: round(v[-1]["iou"], 3) for k, v in rows.items()}, flush=True)
    return rows


def _markdown(args: argparse.Namespace, result: dict[str, Any], target: list, held: list) -> list[str]:
    stats, gaps, report, timing = result["rows"], result["gap_closed"], result["labelling"], result["timing"]
    h, w = result["size"]
    lines = [f"# bsn-adapt across styles: {args.source} -> {args.target}", "",
             f"Source model: trained on `{args.source}` only ({args.train_steps} steps at {h}x{w}, teacher included). "
             f"Adaptation clips: {len(target)} `{args.target}` clips ({', '.join(c.path.name for c in target)}); "
             f"bsn-adapt reads only their frames and camera files. Evaluation: {len(held)} held-out `{args.target}` "
             "clips against their exact T-frame labels, IoU inside V at each model's own threshold. Fine-tuning "
             f"{args.adapt_steps} steps of B per seed (seeds {args.seeds}).", "",
             "| model | IoU mean | std | per seed |", "|---|---|---|---|"]
    for k, v in stats.items():
        lines.append(f"| {k} | {v['mean']:.3f} | {v['std']:.3f} | "
                     + ", ".join(f"{r['iou']:.3f} @ {r['threshold']:.2f}" for r in v["runs"]) + " |")
    lines += ["", "Gap closed by bsn-adapt, (adapt - before) / (exact - before), per seed: "
              + ", ".join(f"{g:.2f}" for g in gaps) + f" (mean {np.nanmean(gaps):.2f}).", "",
              "bsn-adapt's labels: " + ", ".join(
                  f"{n}: {c.get('label_frames', 0)} frames, depth from the {c.get('label_depth')}"
                  + (f" (the depth head refused: {c['model_depth_rejected']})" if "model_depth_rejected" in c
                     else "")
                  + f", depth/landmark correlation {c.get('depth')}"
                  for n, c in report["clips"].items())
              + ("; rejected: " + "; ".join(f"{n}: {r}" for n, r in report["rejected"].items())
                 if report["rejected"] else "") + ".",
              "", f"Time: {json.dumps(timing)}."]
    return lines


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    work = Path(args.work)
    h, w = (int(v) for v in args.size.split(","))
    label = "T5s"
    t0 = time.perf_counter()
    src = work / f"run_{args.source}"
    _source_model(args, src, h, w)
    timing = {"source_training_s": round(time.perf_counter() - t0, 1)}
    target = [c for c in find_clips(args.data, label) if c.style == args.target]
    held = [c for c in find_clips(args.eval, label) if c.style == args.target]
    if not target or not held:
        raise SystemExit(f"no {args.target} clips in {args.data} or {args.eval}")
    t1 = time.perf_counter()
    folder = AdaptFolder(work / "adapt_labels")
    report: dict[str, Any] = {"clips": {}, "rejected": {}}
    pseudo = label_clips(Run(src), [c.path for c in target], folder, AdaptConfig(label_depth=args.label_depth), None,
                         None, report)
    timing["bsn_adapt_labelling_s"] = round(time.perf_counter() - t1, 1)
    if not pseudo:          # a refusal with its reasons is the measured result
        why = "; ".join(f"{n}: {r}" for n, r in report["rejected"].items())
        lines = [f"# bsn-adapt across styles: {args.source} -> {args.target}", "",
                 f"bsn-adapt refused every {args.target} clip for the `{args.source}` model: {why}."]
        return Report({"source": args.source, "target": args.target, "refused": report, "timing": timing}, lines,
                      lines)
    rows = _tuned(args, src, pseudo, target, held, label)
    timing["total_s"] = round(time.perf_counter() - t0, 1)
    b = rows["before"][0]["iou"]
    gaps = [(a["iou"] - b) / (e["iou"] - b) if e["iou"] > b else float("nan")
            for a, e in zip(rows["bsn-adapt"], rows["exact labels"], strict=True)]
    stats = {k: {"mean": float(np.mean([r["iou"] for r in v])), "std": float(np.std([r["iou"] for r in v])),
                 "runs": v} for k, v in rows.items()}
    result = {"source": args.source, "target": args.target, "seeds": args.seeds, "size": [h, w],
              "train_steps": args.train_steps, "adapt_steps": args.adapt_steps, "rows": stats,
              "adapt_config": AdaptConfig(label_depth=args.label_depth).to_dict(),
              "gap_closed": gaps, "labelling": report, "timing": timing,
              "target_clips": [c.path.name for c in target], "held_out_clips": [c.path.name for c in held]}
    lines = _markdown(args, result, target, held)
    return Report(result, lines, lines)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
