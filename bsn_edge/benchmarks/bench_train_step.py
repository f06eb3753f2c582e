"""Training throughput, before and after each lever, side by side in one run.

    python -m bsn_edge.benchmarks.bench_train_step --data DIR [--clips 8] [--steps 6] [--rounds 3] [--size 256x512]

A step is what ``bsn-train`` does per step (``bsn_edge.train.trainer``: the batch from the data
stream, D + B forward and backward, the teacher's distillation, the Adam update and its schedule),
batch 8 at ``--size`` (the runtime's 256x512 by default), on the labelled clips under DIR. The
levers are added one at a time:

1. before: every sample decoded and warped from its PNGs every step (``data.cache=off``), the
   teacher run every step, fp32, contiguous layout
2. + the sample cache (``data.cache``): decoded and warped once, the batch augmented as tensors
3. + the teacher's features computed once per frame (plain and flipped) and read from the cache
4. + channels-last layout (``train.channels_last``)
5. + torch's fused Adam (one kernel for every parameter's update), and the same without
   channels-last (``bsn-train`` keeps the per-tensor Adam: the fused one did not pay on a 2-core EPYC)
6. 4 + bf16 autocast (``train.precision``), only on a CPU with native bf16 (AMX or AVX-512 BF16)

The configurations take turns for ``--rounds`` rounds of ``--steps`` steps (after a warm-up
each), and each reports its median step. One-off costs (building the cache, the teacher's
features) are reported apart, per frame.

``--model`` takes several architectures, measured side by side in the same turns; ``--as-trained``
keeps only what ``bsn-train`` runs on this CPU (4, and 6 where the CPU has native bf16), and the
report then gives the hours a run of ``--budget`` steps takes at that rate (its validation records
not counted): what a table that trains every architecture to a plateau costs on this machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from typing import Any

import torch

from bsn_edge.cli.common import parse_size
from bsn_edge.data import BlindSpotDataset, find_clips
from bsn_edge.data.cache import SampleCache
from bsn_edge.networks import create_model, create_teacher, get_spec
from bsn_edge.train.batches import training_batches
from bsn_edge.train.config import load_config
from bsn_edge.train.device import autocast_dtype, cpu_has_native_bf16, layout, scaled
from bsn_edge.train.optim import Optimizer
from bsn_edge.train.trainer import losses

from .runner import Report, run

_BEFORE = {"cache": False, "teacher_grid": False, "channels_last": False, "precision": "fp32", "fused": False}
LEVERS = [
    ("before", _BEFORE),
    ("+ sample cache", {**_BEFORE, "cache": True}),
    ("+ teacher features cached", {**_BEFORE, "cache": True, "teacher_grid": True}),
    ("+ channels last", {**_BEFORE, "cache": True, "teacher_grid": True, "channels_last": True}),
    ("+ fused Adam", {**_BEFORE, "cache": True, "teacher_grid": True, "channels_last": True, "fused": True}),
    ("cached, contiguous, fused Adam", {**_BEFORE, "cache": True, "teacher_grid": True, "fused": True}),
    ("channels last + bf16 autocast", {**_BEFORE, "cache": True, "teacher_grid": True, "channels_last": True,
                                       "precision": "bf16"}),
]
# what bsn-train runs: channels-last with the cached teacher features, in fp32 or (native bf16) autocast
AS_TRAINED = ("+ channels last", "channels last + bf16 autocast")


class Setup:
    """One configuration: its model, optimizer and batch stream, stepped on demand."""

    def __init__(self, name: str, lever: dict[str, Any], ds: BlindSpotDataset, cache: SampleCache, grid_cache,
                 batch: int, model_name: str) -> None:
        self.name = name
        self.cfg = load_config(None, [f'model.name="{model_name}"', f"train.batch_size={batch}",
                                      f"train.channels_last={str(lever['channels_last']).lower()}",
                                      f"train.precision=\"{lever['precision']}\"",
                                      "train.depth_object_weight=5", "train.depth_grad_scales=4"])
        self.cfg = dataclasses.replace(self.cfg, data=dataclasses.replace(self.cfg.data, size=ds.size))
        torch.manual_seed(0)
        self.model = create_model(model_name)
        cl = lever["channels_last"]
        # torch's stubs lack Module.to's memory_format, which torch takes (channels-last weights)
        self.model.to(memory_format=torch.channels_last if cl else torch.contiguous_format).train()  # type: ignore[call-overload]
        self.teacher = create_teacher("resnet18", 128).eval()
        self.teacher.to(memory_format=torch.channels_last if cl else torch.contiguous_format)  # type: ignore[call-overload]
        self.opt = Optimizer(self.model.parameters(), 1e-3, 100_000, self.cfg.train, fused=lever["fused"])
        self.dtype = autocast_dtype(self.cfg, torch.device("cpu"))
        source = (grid_cache if lever["teacher_grid"] else cache) if lever["cache"] else None
        self.batches = training_batches(ds, source, batch, 1, 0, 0, 0)
        self.times: list[float] = []

    def step(self, record: bool) -> None:
        t0 = time.perf_counter()
        b = next(self.batches)
        loss, *_ = losses(self.model, b, self.teacher, self.cfg, self.dtype)
        self.opt.step(loss)
        if record:
            self.times.append(time.perf_counter() - t0)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="folder of labelled sequence folders (256x512 or any size)")
    p.add_argument("--clips", type=int, default=8, help="clips used (the first N found)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--steps", type=int, default=6, help="timed steps per configuration and round")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--model", nargs="+", default=["small-light"], help="architectures, side by side")
    p.add_argument("--size", type=parse_size, default=(256, 512), metavar="HxW",
                   help="training size (the runtime's 256x512; the research tables' 128x256)")
    p.add_argument("--as-trained", action="store_true",
                   help="only the configurations bsn-train runs on this CPU (channels-last; bf16 where native)")
    p.add_argument("--budget", type=int, default=12_000, help="steps of a run, for the hours column")
    p.add_argument("--name", default="train_step", help="report name in --out")
    return p


def _caches(ds: BlindSpotDataset) -> tuple[SampleCache, SampleCache, float, float]:
    """The sample cache and a copy with the teacher's features, and what each cost per frame (seconds)."""
    t0 = time.perf_counter()
    cache = SampleCache.for_dataset(ds, None)
    build_s = (time.perf_counter() - t0) / len(ds)
    grid_cache = SampleCache(cache.arrays, cache.items, cache.key)
    teacher = create_teacher("resnet18", 128)
    t0 = time.perf_counter()
    grid_cache.attach_teacher(teacher.eval(), 0.5, (8, 16), resize=lambda x, s: layout(scaled(x, s), True))
    return cache, grid_cache, build_s, (time.perf_counter() - t0) / len(ds)


def _timed(args: argparse.Namespace, ds, cache, grid_cache) -> list[dict[str, Any]]:
    """Each architecture's configurations stepped in turn, round by round; their median steps."""
    levers = [(n, lv) for n, lv in LEVERS if lv["precision"] != "bf16" or cpu_has_native_bf16()]
    if args.as_trained:
        # bf16 is already gone where the CPU has no native bf16: the last one left is what bsn-train runs
        levers = [(n, lv) for n, lv in levers if n in AS_TRAINED][-1:]
    setups = {m: [Setup(n, lv, ds, cache, grid_cache, args.batch, m) for n, lv in levers] for m in args.model}
    every = [s for group in setups.values() for s in group]
    for s in every:
        s.step(False)
        s.step(False)
    for _ in range(args.rounds):
        for s in every:
            s.step(False)                       # the other configurations ran since: one untimed step
            for _ in range(args.steps):
                s.step(True)
    rows = []
    for m, group in setups.items():
        base = statistics.median(group[0].times)
        for s in group:
            med = statistics.median(s.times)
            rows.append({"model": m, "config": s.name, "seconds_per_step": med,
                         "samples_per_second": args.batch / med, "speedup": base / med,
                         "budget_hours": med * args.budget / 3600, "n": len(s.times)})
    return rows


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    if args.steps < 1 or args.rounds < 1 or args.budget < 1:
        p.error("--steps, --rounds and --budget must be at least 1")
    for m in args.model:
        try:
            get_spec(m)
        except ValueError as e:
            p.error(f"--model: {e}")
    torch.set_num_threads(2)
    try:
        clips = find_clips(args.data)[: args.clips]
    except (FileNotFoundError, ValueError) as e:
        p.error(f"--data: {e}")
    size = args.size
    cam_cfg = load_config(None, [f"data.size=[{size[0]}, {size[1]}]"]).data
    camera, mounting = cam_cfg.model_camera()
    ds = BlindSpotDataset(clips, size, augment=True, camera=camera, mounting=mounting, seed=0)
    cache, grid_cache, build_s, teacher_s = _caches(ds)
    rows = _timed(args, ds, cache, grid_cache)
    res = {"models": args.model, "batch": args.batch, "size": list(size), "threads": 2, "frames": len(ds),
           "clips": [c.path.name for c in clips], "cache_build_ms_per_frame": 1e3 * build_s,
           "teacher_features_ms_per_frame": 1e3 * teacher_s, "native_bf16": cpu_has_native_bf16(),
           "budget_steps": args.budget, "rows": rows}
    names = ", ".join(f"`{m}`" for m in args.model)
    title = "Training step as bsn-train runs it here" if args.as_trained else "Training step, lever by lever"
    lines = [f"# {title}\n\n{names}, batch {args.batch} at {size[0]}x{size[1]}, D + B + "
             f"the teacher's distillation + Adam, 2 threads, on {len(clips)} labelled clips ({len(ds)} frames); "
             f"configurations in turn, {args.rounds} rounds of {args.steps} steps, median step.\n",
             f"| model | configuration | s / step | samples / s | vs first | h for {args.budget:,} steps |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['model']} | {r['config']} | {r['seconds_per_step']:.3f} | {r['samples_per_second']:.1f} | "
              f"{r['speedup']:.2f}x | {r['budget_hours']:.2f} |" for r in rows]
    lines.append(f"\nOne-off per frame: the sample cache {1e3 * build_s:.1f} ms, the teacher's features "
                 f"(plain and flipped) {1e3 * teacher_s:.1f} ms. Hours: the median step times the steps, "
                 "without the run's validation records.")
    if not cpu_has_native_bf16():
        lines.append("\nThis CPU has no native bf16 (AMX or AVX-512 BF16): `train.precision=auto` trains in fp32 here.")
    return Report(res, lines, lines)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
