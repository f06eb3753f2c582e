"""Which optimizer keeps the network alive: alive channels over a run, under each setting, side by side.

    python -m benchmarks.bench_optimizer [--variant small-light] [--steps 3000] [--every 250] --out benchmarks/results

The shipped variant, fresh, trained by the project's own :class:`~bsn_edge.train.optim.Optimizer` on
fixed random frames whose targets it cannot all fit (blind spots and depth from coarse noise, batch 8 at
64x128, lr 1e-3, the schedule of a run of ``--steps``), so that most channels soon have little gradient
of their own: the regime in which weight decay decides whether they live. The settings:

- ``adam``: Adam with L2 decay 5e-4 on every parameter (the recipe the default was trained with);
- ``adamw-all``: decoupled decay 1e-2 on every parameter, normalisation scales and biases included;
- ``adamw`` (the default): decoupled decay 1e-2 on convolution and linear weights only.

Alive channels (``bsn_edge.models.alive``) every ``--every`` steps. No timing: the figures are counts.
Subnormal floats are flushed to zero (a collapsing run otherwise slows several times over).
"""

from __future__ import annotations

import argparse
from typing import Any

import torch
import torch.nn.functional as F

from bsn_edge.models import create_model
from bsn_edge.models.alive import alive_channels
from bsn_edge.train.config import ADAM, ADAMW, TrainConfig
from bsn_edge.train.optim import Optimizer

from .common import machine
from .runner import Report, run

LR = 1e-3
SIZE = (64, 128)
BATCH = 8
# name: (optimizer, weight decay, whether normalisation scales and biases are decayed too)
SETTINGS = {"adam": (ADAM, 5e-4, True), "adamw-all": (ADAMW, 1e-2, True), "adamw": (ADAMW, 1e-2, False)}


def _batch(seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(BATCH, 3, *SIZE, generator=g)
    coarse = (BATCH, 1, SIZE[0] // 8, SIZE[1] // 8)
    target = (F.interpolate(torch.rand(coarse, generator=g), size=SIZE) > 0.6).float()
    depth = F.interpolate(torch.rand(coarse, generator=g), size=SIZE) * 50 + 2
    return x, target, depth


def curve(variant: str, setting: str, steps: int, every: int) -> list[dict[str, Any]]:
    """Alive channels at step 0 and every ``every`` steps of one setting's run."""
    kind, decay, all_params = SETTINGS[setting]
    torch.manual_seed(0)
    model = create_model(variant).train()
    t = TrainConfig(optimizer=kind, weight_decay=decay)
    optim = Optimizer(model.parameters(), LR, steps, t)
    if all_params and kind == ADAMW:        # the scales and biases decayed too: the split undone
        for g in optim.opt.param_groups:
            g["weight_decay"] = decay
    x, target, depth = _batch(0)
    out = [{"step": 0, **alive_channels(model).to_dict()}]
    for step in range(1, steps + 1):
        blind, d, _ = model(x)
        optim.step(F.binary_cross_entropy_with_logits(blind, target) + (d - depth).abs().mean() / 10)
        if step % every == 0 or step == steps:
            out.append({"step": step, **alive_channels(model).to_dict()})
            print(f"{setting} step {step}: {100 * out[-1]['alive_share']:.1f} % alive", flush=True)
    return out


def measure(args: argparse.Namespace, _parser: argparse.ArgumentParser) -> Report:
    torch.set_num_threads(2)
    # weights walking to zero pass through subnormal floats, which x86 multiplies a hundred times slower:
    # flushed to zero, every setting runs at full speed (a weight under 1e-38 is zero to every count here)
    torch.set_flush_denormal(True)
    curves = {s: curve(args.variant, s, args.steps, args.every) for s in args.settings}
    result = {"machine": machine(), "variant": args.variant, "steps": args.steps, "lr": LR, "size": SIZE,
              "batch": BATCH, "curves": curves}
    md = ["# Alive channels by optimizer", "",
          f"`{args.variant}`, fresh, on fixed random frames (batch {BATCH} at {SIZE[0]}x{SIZE[1]}, lr {LR:g}, "
          f"{args.steps} steps): the share of its {curves[args.settings[0]][0]['channels']:,} convolution channels "
          "alive (`benchmarks/bench_optimizer.py`).", "",
          "| step | " + " | ".join(args.settings) + " |", "|---|" + "---|" * len(args.settings)]
    for i, rec in enumerate(curves[args.settings[0]]):
        md.append(f"| {rec['step']} | " + " | ".join(f"{100 * curves[s][i]['alive_share']:.1f} %"
                                                      for s in args.settings) + " |")
    return Report(result, md)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="bench_optimizer", description=__doc__.split("\n\n")[0])
    p.add_argument("--variant", default="small-light")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--every", type=int, default=250)
    p.add_argument("--settings", nargs="*", choices=list(SETTINGS), default=list(SETTINGS))
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="optimizer")
    return run(measure, p, argv)


if __name__ == "__main__":
    raise SystemExit(main())
