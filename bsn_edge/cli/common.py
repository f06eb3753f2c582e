"""Small helpers shared by the command-line tools."""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

# the source checkout this package runs from (editable install): benchmarks/ and models/ live here
CHECKOUT_ENV = "BSN_EDGE_CHECKOUT"
# the source tree: $BSN_EDGE_CHECKOUT (bsn-bench sets it for the benchmarks it runs on a tree it was given), else
# the one the package sits in (an installed wheel's site-packages: none)
CHECKOUT = Path(os.environ.get(CHECKOUT_ENV) or Path(__file__).resolve().parents[2]).resolve()
REAL_DATA_ENV = "BSN_EDGE_REAL_DATA"
# the real development data: $BSN_EDGE_REAL_DATA, else beside the checkout (tests and benchmarks that need it
# skip without it)
REAL_DATA = Path(os.environ.get(REAL_DATA_ENV) or CHECKOUT.parent / "shared" / "data" / "real")


def parse_size(text: str) -> tuple[int, int]:
    """``HxW`` (e.g. ``256x512``) to ``(height, width)``; argparse-friendly errors."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        if re.fullmatch(r"\s*[-+]?\d+(\.\d*)?\s*[xX]\s*[-+]?\d+(\.\d*)?\s*", text):
            raise argparse.ArgumentTypeError(f"size must be two positive whole numbers of pixels, HEIGHTxWIDTH "
                                             f"(e.g. 256x512), got {text!r}")
        raise argparse.ArgumentTypeError(f"size must look like HEIGHTxWIDTH (e.g. 256x512), got {text!r}")
    h, w = int(m.group(1)), int(m.group(2))
    if h < 16 or w < 16:
        raise argparse.ArgumentTypeError(f"size must be at least 16x16, got {h}x{w}")
    return h, w


def glue_values(argv: list[str] | None, options: tuple[str, ...] = ("--size",)) -> list[str]:
    """``argv`` with ``OPTION VALUE`` written ``OPTION=VALUE`` for ``options`` whose value starts with
    '-' (argparse would take ``--size -5x10`` for two options and say "expected one argument" instead
    of what is wrong with the value)."""
    args = list(sys.argv[1:] if argv is None else argv)
    out: list[str] = []
    i = 0
    while i < len(args):
        if args[i] in options and i + 1 < len(args) and args[i + 1].startswith("-") and len(args[i + 1]) > 1 \
                and args[i + 1][1].isdigit():
            out.append(f"{args[i]}={args[i + 1]}")
            i += 2
        else:
            out.append(args[i])
            i += 1
    return out


def fail(prog: str, message: str, code: int = 2) -> int:
    """Print ``prog: error: message`` to stderr and return ``code``."""
    print(f"{prog}: error: {message}", file=sys.stderr)
    return code
