"""Reading a sequence's RGB frames."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def read_rgb(seq: str | Path, i: int) -> np.ndarray:
    """BGR frame ``i`` of a sequence folder (``rgb/NNNNNN.png`` or ``.jpg``)."""
    seq = Path(seq)
    for ext in (".png", ".jpg"):
        p = seq / "rgb" / f"{i:06d}{ext}"
        if p.exists():
            img = cv2.imread(str(p), cv2.IMREAD_COLOR)
            if img is None:
                raise ValueError(f"{p}: unreadable image")
            return img
    raise FileNotFoundError(f"{seq}: no rgb/{i:06d}.png or .jpg")


def read_gray(seq: str | Path, i: int) -> np.ndarray:
    return cv2.cvtColor(read_rgb(seq, i), cv2.COLOR_BGR2GRAY)
