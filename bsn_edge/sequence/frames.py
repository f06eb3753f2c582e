"""Reading a sequence's RGB frames."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from bsn_edge.sequence.folder import SequenceFolder


def read_rgb(seq: str | Path, i: int) -> np.ndarray:
    """BGR frame ``i`` of a sequence folder."""
    p = SequenceFolder(seq).rgb(i)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such frame image")
    img = cv2.imread(str(p), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"{p}: unreadable image")
    return img


def read_gray(seq: str | Path, i: int) -> np.ndarray:
    return cv2.cvtColor(read_rgb(seq, i), cv2.COLOR_BGR2GRAY)
