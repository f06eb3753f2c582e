"""``bsn-sheet``: a contact sheet PNG of one or more sequence folders."""

from __future__ import annotations

import argparse

from bsn_edge.cli.common import fail
from bsn_edge.cli.outputs import OutputKind, check_output
from bsn_edge.sequence import write_image
from bsn_edge.synth.sheet import contact_sheet

PROG = "bsn-sheet"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Write a contact sheet (RGB, depth, semantics, blind spots tinted red) of "
                    "sequence folders, for a person to judge.")
    p.add_argument("seqs", nargs="+", help="sequence folders")
    p.add_argument("--out", required=True, help="output PNG")
    p.add_argument("--rows", type=int, default=3, help="frames per sequence (default 3)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.rows < 1:
        return fail(PROG, f"--rows must be >= 1, got {args.rows}")
    try:
        out = check_output(OutputKind("--out", (".png",), "contact sheet"), args.out, args.force)
        img = contact_sheet(args.seqs, rows=args.rows)
        write_image(out, img)
    except (FileNotFoundError, FileExistsError, ValueError, OSError) as e:
        return fail(PROG, str(e))
    print(f"wrote {out} ({img.shape[0]}x{img.shape[1]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
