"""``bsn-demo``: the main job on the built-in default, end to end, in one command."""

from __future__ import annotations

import argparse
from pathlib import Path

from bsn_edge.cli import sheet, synth

PROG = "bsn-demo"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Run the main job on the built-in synthetic world: render a town and a suburb "
                    "clip and write their contact sheet.")
    p.add_argument("--out", default="demo", help="output folder (default ./demo)")
    p.add_argument("--frames", type=int, default=100, help="frames per clip (default 100)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    seqs = []
    for style in ("town", "suburb"):
        seq = out / f"{style}_{args.seed}"
        rc = synth.main([str(seq), "--frames", str(args.frames), "--style", style,
                         "--seed", str(args.seed), "--force"])
        if rc:
            return rc
        seqs.append(str(seq))
    return sheet.main([*seqs, "--out", str(out / "contact_sheet.png")])


if __name__ == "__main__":
    raise SystemExit(main())
