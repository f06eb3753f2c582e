"""Interpolate two runs of one architecture in weight space (a "soup" of a fine-tuned leg and the run
it started from: the start's knowledge kept, part of the leg's gain taken), choose its threshold on the
validation clips of the leg's config, and write it as a run, shipped in fp16 like the legs.

    python models/campaign/soup.py START LEG ALPHA DATA OUT

ALPHA is the leg's share (0: START, 1: LEG). Batch-norm statistics are interpolated like the weights
(both runs come from one start, so their statistics are near each other). The checkpoint records
``soup`` = {start, leg, alpha}. Run from the campaign folder (DATA: its data/ folder).
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import torch

from bsn_edge.config_toml import build
from bsn_edge.networks import ModelSpec
from bsn_edge.train.batches import datasets
from bsn_edge.train.checkpoints import save_checkpoint
from bsn_edge.train.config import SECTIONS, Config
from bsn_edge.train.run import Run
from bsn_edge.train.ship import ship_run
from bsn_edge.train.validation import choose_threshold


def mixed_state(start: dict[str, torch.Tensor], leg: dict[str, torch.Tensor], alpha: float) -> dict[str, torch.Tensor]:
    if start.keys() != leg.keys():
        raise ValueError(f"the runs differ in their tensors: {sorted(start.keys() ^ leg.keys())[:5]}")
    return {k: ((1 - alpha) * start[k].float() + alpha * v.float()) if v.is_floating_point() else v
            for k, v in leg.items()}


def leg_config(leg_run: Run) -> Config:
    """The leg's training config, as its run recorded it."""
    raw = leg_run.config()
    return Config(**{s: build(SECTIONS[s], v, s, str(leg_run.config_path), set()) for s, v in raw.items()})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("start")
    ap.add_argument("leg")
    ap.add_argument("alpha", type=float)
    ap.add_argument("data")
    ap.add_argument("out")
    a = ap.parse_args(argv)
    if not 0 <= a.alpha <= 1:
        raise SystemExit(f"alpha must be in [0, 1], got {a.alpha}")
    start_model, start_card = Run(a.start).load_model()
    leg_run = Run(a.leg)
    leg_model, leg_card = leg_run.load_model()
    if ModelSpec(**start_card.spec) != ModelSpec(**leg_card.spec):
        raise SystemExit("the runs are of different architectures")
    leg_model.load_state_dict(mixed_state(start_model.state_dict(), leg_model.state_dict(), a.alpha))
    cfg = leg_config(leg_run)
    data = datasets(cfg, a.data)
    threshold, val = choose_threshold(leg_model, data.val_ds)
    with tempfile.TemporaryDirectory() as tmp:
        work = ship_run(leg_run, Path(tmp) / "soup")
        save_checkpoint(work, leg_model, cfg, data, cfg.train.steps, threshold=threshold, val=val)
        record = json.loads(work.checkpoint_path.read_text())
        record["soup"] = {"start": Path(a.start).name, "leg": Path(a.leg).name, "alpha": a.alpha}
        work.checkpoint_path.write_text(json.dumps(record, indent=2) + "\n")
        ship_run(work, a.out)
    print(f"{a.out}: alpha {a.alpha}, threshold {threshold:.2f}, val {val}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
