"""Contact sheets: a grid a person can judge a sequence folder by.

One row per sampled frame: RGB, depth, semantics, and true blind spots (or labels)
tinted over the RGB.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.sequence import SequenceMeta, read_depth, read_mask
from bsn_edge.sequence.folder import SequenceFolder

BS_TINT = np.array([40, 40, 255], np.float32)  # BGR red
HEADER = 22


def colorize_depth(depth: np.ndarray, max_m: float = 80.0) -> np.ndarray:
    """Inverse-depth colour map (near bright); no-depth pixels black."""
    with np.errstate(divide="ignore"):
        inv = np.where(depth > 0, np.clip(1.0 / np.maximum(depth, 1e-3), 1.0 / max_m, 1.0), 0.0)
    scaled = np.clip((inv - 1.0 / max_m) / (1.0 / 2.0 - 1.0 / max_m), 0, 1)
    img = cv2.applyColorMap((np.sqrt(scaled) * 255).astype(np.uint8), cv2.COLORMAP_MAGMA)
    img[depth <= 0] = 0
    return img


def tint(rgb: np.ndarray, mask: np.ndarray, color: np.ndarray = BS_TINT, alpha: float = 0.6) -> np.ndarray:
    """Blend ``color`` over ``rgb`` where ``mask`` is set."""
    out = rgb.astype(np.float32)
    out[mask] = out[mask] * (1 - alpha) + color * alpha
    return out.astype(np.uint8)


def _label(img: np.ndarray, text: str) -> np.ndarray:
    bar = np.full((HEADER, img.shape[1], 3), 255, np.uint8)
    cv2.putText(bar, text, (6, HEADER - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([bar, img])


def sequence_rows(seq: str | os.PathLike, rows: int = 3) -> np.ndarray:
    """Rows of a contact sheet for one sequence folder, with a title bar."""
    seq = Path(seq)
    meta = SequenceMeta.read(seq)
    if meta.frames < 1:
        raise ValueError(f"{seq}: sequence has no frames")
    picks = np.unique(np.linspace(0, meta.frames - 1, rows + 2)[1:-1].round().astype(int))
    out = []
    folder = SequenceFolder(seq)
    for i in picks:
        rgb = cv2.imread(str(folder.rgb(i)), cv2.IMREAD_COLOR)
        if rgb is None:
            raise FileNotFoundError(f"{folder.rgb(i)}: missing or unreadable")
        tiles = [rgb]
        depth_p, sem_p, bs_p = folder.depth(i), folder.semantic(i), folder.bsgt(i)
        tiles.append(colorize_depth(read_depth(depth_p)) if depth_p.exists() else np.zeros_like(rgb))
        sem = cv2.imread(str(sem_p), cv2.IMREAD_GRAYSCALE) if sem_p.exists() else None
        tiles.append(sm.colorize(sem) if sem is not None else np.zeros_like(rgb))
        tiles.append(tint(rgb, read_mask(bs_p)) if bs_p.exists() else rgb)
        row = np.hstack(tiles)
        cv2.putText(row, f"#{i}", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        out.append(row)
    grid = np.vstack(out)
    style = meta.extra.get("style", meta.source)
    return _label(grid, f"{seq.name} ({style}, {meta.height}x{meta.width}, {meta.fps:g} fps)   "
                        f"|  RGB  |  depth  |  semantics  |  true blind spots (red)")


def contact_sheet(seqs: list[str | os.PathLike], rows: int = 3) -> np.ndarray:
    """A contact sheet over several sequence folders (stacked vertically)."""
    if not seqs:
        raise ValueError("no sequence folders given")
    parts = [sequence_rows(s, rows) for s in seqs]
    width = max(p.shape[1] for p in parts)
    parts = [np.pad(p, ((0, 6), (0, width - p.shape[1]), (0, 0)), constant_values=255) for p in parts]
    return np.vstack(parts)
