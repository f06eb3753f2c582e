"""Architectures (the paper's Table 3): parameters, GMACs, CPU frames/s and IoU.

    python -m benchmarks.bench_arch --out benchmarks/results --data CLIPS [--train-steps 300]
                                    [--runs small-light=RUN ...]

GMACs are counted by ``torch.utils.flop_counter`` at 256x512 for the whole fused model (D and B).
Frames/s: the fused fp32 ONNX model in onnxruntime, 2 intra-op threads, median of ``--repeats``
runs after warm-up, all in one run of this script.

IoU: with ``--train-steps``, every architecture is trained on ``--data`` with one budget (steps,
batch 8, ``--train-size``, one shared teacher, the 60/20/20 clip split of ``configs/quick.toml``)
and evaluated inside V on the held-out clips, so the column compares architectures, not
budgets. ``--runs`` adds the IoU of runs trained elsewhere (e.g. the shipped model's).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from benchmarks.common import eval_run, summary, time_calls, train_run, write_result
from bsn_edge.camera import Intrinsics
from bsn_edge.cli.common import parse_size
from bsn_edge.export import to_onnx
from bsn_edge.models import create_model, describe
from bsn_edge.runtime.model_file import session

ARCHS = ("unet", "small", "small-light", "medium", "large")


def count_gmacs(model: torch.nn.Module, size: tuple[int, int]) -> float:
    """Multiply-accumulates of one forward pass at ``size`` (H, W), in billions."""
    with FlopCounterMode(display=False) as fc, torch.no_grad():
        model(torch.zeros(1, 3, *size))
    return fc.get_total_flops() / 2e9


def measure(name: str, size: tuple[int, int], repeats: int, workdir: Path) -> dict:
    torch.manual_seed(0)
    m = create_model(name).eval()
    params = sum(p.numel() for p in m.parameters())
    gmacs = count_gmacs(m, size)
    path = workdir / f"{name}.onnx"
    # timing only: any camera of the right size will do
    to_onnx(m, path, describe(name, m, Intrinsics.from_fov(size[1], size[0], 80.0)))
    sess = session(path, threads=2)
    frame = np.random.default_rng(0).integers(0, 256, (1, *size, 3), dtype=np.uint8)
    med = summary(time_calls(lambda _: sess.run(None, {"frame": frame}), repeats, warmup=5))["median_ms"] / 1e3
    return {"model": name, "params_m": round(params / 1e6, 2), "gmacs": round(gmacs, 2),
            "median_ms": round(1e3 * med, 2), "fps": round(1 / med, 2), "repeats": repeats}


def train_uniform(name: str, data: Path, work: Path, steps: int, size: tuple[int, int], teacher: Path | None
                  ) -> Path:
    """Train ``name`` on ``data`` with the benchmark's budget into ``work/name`` (reused if done)."""
    sets = [f"model.name={name}", f"data.size=[{size[0]}, {size[1]}]", "data.val_fraction=0.2",
            "data.test_fraction=0.2", f"train.steps={steps}", "train.batch_size=8", f"train.checkpoint_every={steps}"]
    if teacher is not None:
        sets.append(f"teacher.checkpoint={teacher}")
    return train_run(data, work / name, sets)


def run_budget(run: Path) -> str:
    """How a run was trained, from its resolved config."""
    cfg = json.loads((run / "config.json").read_text())
    h, w = cfg["data"]["size"]
    return f"trained {cfg['train']['steps']} steps of batch {cfg['train']['batch_size']} at {h}x{w}"


def held_out_iou(run: Path, data: Path, report: Path) -> float:
    """IoU inside V of ``run`` on its held-out clips of ``data``, at its training size."""
    return round(eval_run(run, data, report, "--no-baselines")["overall"]["BSN"]["iou"], 4)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--repeats", type=int, default=30)
    p.add_argument("--runs", nargs="*", default=[], metavar="NAME=RUN", help="trained runs for the IoU column")
    p.add_argument("--data", default=None, help="labelled clips: training (--train-steps) and held-out IoU")
    p.add_argument("--train-steps", type=int, default=0, help="train every architecture this many steps (0: no)")
    p.add_argument("--train-size", type=parse_size, default=(128, 256), metavar="HxW", help="training size")
    p.add_argument("--teacher", default=None, help="a trained teacher's folder (default: the first run trains one)")
    p.add_argument("--work", default="benchmarks/scratch/arch", help="runs trained by --train-steps are kept here")
    p.add_argument("--only", nargs="*", choices=ARCHS, default=list(ARCHS), help="architectures to measure")
    args = p.parse_args(argv)
    if (args.train_steps or args.runs) and not args.data:
        p.error("--train-steps and --runs need --data")
    torch.set_num_threads(2)
    size = (256, 512)
    runs = dict(r.split("=", 1) for r in args.runs)
    teacher = Path(args.teacher) if args.teacher else None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.only:
            row = measure(name, size, args.repeats, Path(tmp))
            if args.train_steps:
                run = train_uniform(name, Path(args.data), Path(args.work), args.train_steps, args.train_size,
                                    teacher)
                teacher = teacher or run / "teacher"
                row["iou"] = held_out_iou(run, Path(args.data), Path(tmp) / f"{name}_uniform.json")
            if name in runs:
                row["iou_run"] = held_out_iou(Path(runs[name]), Path(args.data), Path(tmp) / f"{name}.json")
            rows.append(row)
            print(row, flush=True)
    budget = ({"steps": args.train_steps, "batch_size": 8, "size": list(args.train_size),
               "teacher": str(teacher)} if args.train_steps else None)
    res = {"rows": rows, "size": list(size), "threads": 2, "iou_training": budget,
           "iou_run": {k: run_budget(Path(v)) for k, v in runs.items()}}
    lines = ["# Architectures (the paper's Table 3)", "",
             f"Fused D + B at {size[0]}x{size[1]}; frames/s of the fp32 ONNX model in onnxruntime with 2 threads.",
             "", "| model | params (M) | GMACs | ms | frames/s | IoU | IoU (own run) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['model']} | {r['params_m']} | {r['gmacs']} | {r['median_ms']} | {r['fps']} | "
                     f"{r.get('iou', '-')} | {r.get('iou_run', '-')} |")
    if budget:
        lines += ["", f"IoU: inside V on the held-out clips, every model trained {budget['steps']} steps of batch 8 at "
                      f"{budget['size'][0]}x{budget['size'][1]} with one shared teacher and evaluated at that size."]
    if runs:
        lines += ["", "IoU (own run): " + "; ".join(f"`{k}` {run_budget(Path(v))}" for k, v in runs.items())
                  + "; evaluated at its own training size."]
    path = write_result(args.out, "bsn_arch", res, "\n".join(lines))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
