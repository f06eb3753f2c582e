"""Which optimizer keeps the network alive: alive channels over a run, under each setting, side by side.

    python -m bsn_edge.benchmarks.bench_optimizer [--variant shared-light] [--steps 3000] [--schedule 9000] \
        [--every 500] \
        --out benchmarks/results

The shipped variant (or, ``--variant teacher:resnet18``, the default's segmentation teacher), fresh,
trained by the project's own :class:`~bsn_edge.train.optim.Optimizer` on fixed random frames whose
targets it cannot all fit (blind spots and depth, or classes, from coarse noise, batch 8 at 64x128,
lr 1e-3), so that most channels soon have little gradient of their own: the regime in which weight
decay decides whether they live. The learning rate follows the schedule of a campaign leg
(``--schedule`` steps, 9,000 as the default's legs were) and the first ``--steps`` of it are run: a
schedule as short as the run itself decays the rate before the collapse shows. The settings:

- ``adam``: Adam with L2 decay 5e-4 on every parameter (the recipe the default was trained with);
- ``adamw-all``: decoupled decay 1e-2 on every parameter, normalisation scales and biases included;
- ``adamw`` (the default): decoupled decay 1e-2 on convolution and linear weights only.

Alive channels (``bsn_edge.networks.alive``) every ``--every`` steps. No timing: the figures are counts.
Subnormal floats are flushed to zero (a collapsing run otherwise slows several times over).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import torch
import torch.nn.functional as F

from bsn_edge.networks import create_model
from bsn_edge.networks.alive import alive_channels
from bsn_edge.networks.registry import create_teacher
from bsn_edge.semantics import NUM_CLASSES
from bsn_edge.train.config import ADAM, ADAMW, TrainConfig
from bsn_edge.train.optim import Optimizer

from .common import machine
from .runner import Report, run

LR = 1e-3
SIZE = (64, 128)
BATCH = 8
# a --variant of this prefix is the segmentation teacher on the encoder named after it
TEACHER = "teacher:"
# name: (optimizer, weight decay, whether normalisation scales and biases are decayed too)
SETTINGS = {"adam": (ADAM, 5e-4, True), "adamw-all": (ADAMW, 1e-2, True), "adamw": (ADAMW, 1e-2, False)}


def _batch(seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Frames, blind-spot targets, depth, and classes for a teacher (each coarse noise brought up to size)."""
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(BATCH, 3, *SIZE, generator=g)
    coarse = (BATCH, 1, SIZE[0] // 8, SIZE[1] // 8)
    target = (F.interpolate(torch.rand(coarse, generator=g), size=SIZE) > 0.6).float()
    depth = F.interpolate(torch.rand(coarse, generator=g), size=SIZE) * 50 + 2
    classes = F.interpolate(torch.randint(0, NUM_CLASSES, coarse, generator=g).float(), size=SIZE)
    return x, target, depth, classes[:, 0].long()


def _network(variant: str) -> tuple[torch.nn.Module, Callable[[torch.nn.Module, tuple], torch.Tensor]]:
    """The network (the student ``variant``, or the segmentation teacher as ``teacher:ENCODER``) and its
    loss on a batch: blind spots and depth for the student, classes for the teacher."""
    if variant.startswith(TEACHER):
        teacher = create_teacher(variant.removeprefix(TEACHER) or "resnet18")

        def seg_loss(net: torch.nn.Module, b: tuple) -> torch.Tensor:
            return F.cross_entropy(net(b[0])[0], b[3])
        return teacher, seg_loss

    def student_loss(net: torch.nn.Module, b: tuple) -> torch.Tensor:
        blind, d, _ = net(b[0])
        return F.binary_cross_entropy_with_logits(blind, b[1]) + (d - b[2]).abs().mean() / 10
    return create_model(variant), student_loss


def curve(variant: str, setting: str, steps: int, every: int, schedule: int) -> list[dict[str, Any]]:
    """Alive channels at step 0 and every ``every`` steps of one setting's run: the first ``steps`` of a
    learning-rate schedule of ``schedule`` steps (at least ``steps``)."""
    kind, decay, all_params = SETTINGS[setting]
    torch.manual_seed(0)
    model, loss = _network(variant)
    model.train()
    t = TrainConfig(optimizer=kind, weight_decay=decay)
    optim = Optimizer(model.parameters(), LR, schedule, t)
    if all_params and kind == ADAMW:        # the scales and biases decayed too: the split undone
        for g in optim.opt.param_groups:
            g["weight_decay"] = decay
    batch = _batch(0)
    out: list[dict[str, Any]] = [{"step": 0, **alive_channels(model).to_dict()}]
    for step in range(1, steps + 1):
        optim.step(loss(model, batch))
        if step % every == 0 or step == steps:
            out.append({"step": step, **alive_channels(model).to_dict()})
            print(f"{setting} step {step}: {100 * out[-1]['alive_share']:.1f} % alive", flush=True)
    return out


def measure(args: argparse.Namespace, _parser: argparse.ArgumentParser) -> Report:
    torch.set_num_threads(2)
    # weights walking to zero pass through subnormal floats, which x86 multiplies a hundred times slower:
    # flushed to zero, every setting runs at full speed (a weight under 1e-38 is zero to every count here)
    torch.set_flush_denormal(True)
    schedule = max(args.schedule, args.steps)
    curves = {s: curve(args.variant, s, args.steps, args.every, schedule) for s in args.settings}
    result = {"machine": machine(), "variant": args.variant, "steps": args.steps, "schedule": schedule, "lr": LR,
              "size": SIZE, "batch": BATCH, "curves": curves}
    channels = curves[args.settings[0]][0]["channels"]
    md = ["# Alive channels by optimizer", "",
          f"`{args.variant}`, fresh, on fixed random frames (batch {BATCH} at {SIZE[0]}x{SIZE[1]}, lr {LR:g}, "
          f"the first {args.steps:,} steps of a {schedule:,}-step schedule): the share of its {channels:,} "
          "convolution channels alive (`bsn_edge.networks.alive`, `bsn_edge/benchmarks/bench_optimizer.py`).", "",
          "| step | " + " | ".join(args.settings) + " |", "|---|" + "---|" * len(args.settings)]
    for i, rec in enumerate(curves[args.settings[0]]):
        md.append(f"| {rec['step']} | " + " | ".join(f"{100 * curves[s][i]['alive_share']:.1f} %"
                                                      for s in args.settings) + " |")
    return Report(result, md)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="bench_optimizer", description=__doc__.split("\n\n")[0])
    p.add_argument("--variant", default="shared-light",
                   help="the student variant (default: the shipped one's), or the segmentation "
                   f"teacher as {TEACHER}ENCODER ({TEACHER}resnet18: the default's teacher)")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--schedule", type=int, default=9000,
                   help="the learning-rate schedule's length in steps (a campaign leg's); at least --steps")
    p.add_argument("--every", type=int, default=500)
    p.add_argument("--settings", nargs="*", choices=list(SETTINGS), default=list(SETTINGS))
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="optimizer")
    return run(measure, p, argv)


if __name__ == "__main__":
    raise SystemExit(main())
