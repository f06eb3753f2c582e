"""Small helpers shared by the command-line tools."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

# the source checkout this package runs from (editable install): benchmarks/ and models/ live here
CHECKOUT = Path(__file__).resolve().parents[2]


def parse_size(text: str) -> tuple[int, int]:
    """``HxW`` (e.g. ``256x512``) to ``(height, width)``; argparse-friendly errors."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"size must look like HEIGHTxWIDTH (e.g. 256x512), got {text!r}")
    h, w = int(m.group(1)), int(m.group(2))
    if h < 16 or w < 16:
        raise argparse.ArgumentTypeError(f"size must be at least 16x16, got {h}x{w}")
    return h, w


def fail(prog: str, message: str, code: int = 2) -> int:
    """Print ``prog: error: message`` to stderr and return ``code``."""
    print(f"{prog}: error: {message}", file=sys.stderr)
    return code
