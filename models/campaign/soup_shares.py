"""Validation IoU of a soup (``soup.py``) at several shares of the leg, before one is made and judged:
for each share, the threshold with the best IoU inside V on the validation clips of the leg's config,
read from each data folder given (the paper's V in data/, road users unknown in data_uu/). The share is
chosen on these validation clips, never on a held-out set or a real drive.

    python models/campaign/soup_shares.py START LEG DATA[,DATA2] ALPHA[,ALPHA2,...]

Prints one JSON line per share and data folder. Run from the campaign folder.
"""
from __future__ import annotations

import argparse
import json

from soup import leg_config, mixed_state

from bsn_edge.train.batches import datasets
from bsn_edge.train.run import Run
from bsn_edge.train.validation import choose_threshold


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("start")
    ap.add_argument("leg")
    ap.add_argument("data", help="data folders, comma-separated")
    ap.add_argument("alphas", help="the leg's shares, comma-separated, each in [0, 1]")
    a = ap.parse_args(argv)
    alphas = [float(x) for x in a.alphas.split(",")]
    if not all(0 <= x <= 1 for x in alphas):
        raise SystemExit(f"every share must be in [0, 1], got {a.alphas}")
    start_model, _ = Run(a.start).load_model()
    leg_run = Run(a.leg)
    leg_model, _ = leg_run.load_model()
    start = start_model.state_dict()
    # load_state_dict copies into the very tensors state_dict() handed out: keep the leg's own apart
    leg = {k: v.clone() for k, v in leg_model.state_dict().items()}
    cfg = leg_config(leg_run)
    val = {d: datasets(cfg, d).val_ds for d in a.data.split(",")}
    for alpha in alphas:
        leg_model.load_state_dict(mixed_state(start, leg, alpha))
        for d, ds in val.items():
            threshold, figures = choose_threshold(leg_model, ds)
            print(json.dumps({"alpha": alpha, "data": d, "threshold": round(threshold, 2),
                              **{k: round(v, 4) for k, v in figures.items()}}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
