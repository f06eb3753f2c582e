"""Seconds per training step (D + B + distillation, batch 8, 256x512) on this machine's CPU."""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from benchmarks.common import write_result
from bsn_edge.models import create_model, create_teacher
from bsn_edge.train.losses import depth_loss, distillation_loss, masked_bce
from bsn_edge.train.trainer import scaled


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--steps", type=int, default=8)
    p.add_argument("--model", default="small-light")
    args = p.parse_args(argv)
    torch.set_num_threads(2)
    torch.manual_seed(0)
    m, teacher = create_model(args.model), create_teacher(18, 128).eval()
    opt = torch.optim.Adam(m.parameters(), 1e-3)
    b = 8
    x = torch.randn(b, 3, 256, 512)
    y = (torch.rand(b, 1, 256, 512) > 0.9).float()
    v = torch.ones(b, 1, 256, 512)
    d = torch.rand(b, 1, 256, 512) * 50 + 1
    times = []
    for i in range(args.steps + 2):
        t0 = time.perf_counter()
        logits, depth, feats = m(x)
        with torch.no_grad():
            _, tf = teacher(scaled(x, 0.5))
        loss = masked_bce(logits, y, v) + depth_loss(depth, d) + distillation_loss(feats, tf)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if i >= 2:
            times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    res = {"model": args.model, "batch": b, "size": [256, 512], "seconds_per_step": med,
           "samples_per_second": b / med, "threads": 2}
    md = f"# Training step\n\n`{args.model}`, batch {b} at 256x512 with the teacher's distillation, 2 threads: " \
         f"{med:.2f} s per step ({b / med:.1f} samples/s), median of {len(times)}."
    write_result(args.out, "train_step", res, md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
