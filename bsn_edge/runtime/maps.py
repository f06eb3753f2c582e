"""``bsn-run --save-maps DIR``: the model's outputs per frame, on the raw frame's own pixels.

``<name>_blindspot.png``: 8-bit blind-spot probability x 255. ``<name>_depth.png``: 16-bit depth
in metres x 256 (0 = none; the KITTI convention, so common depth tools read it). ``<name>`` is
the source image's stem, or the frame number for a video or a camera.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.sequence.images import atomic_write_bytes

DEPTH_SCALE = 256.0


SUFFIXES = ("blindspot", "depth")


class MapWriter:
    """Owns the ``--save-maps`` folder. A folder that already holds maps is refused unless
    ``overwrite``: a shorter run into it would leave an earlier run's maps among its own."""

    def __init__(self, folder: str | Path, overwrite: bool = False) -> None:
        self.folder = Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise ValueError(f"--save-maps {self.folder}: exists and is not a folder")
        if self.folder.is_dir() and not overwrite:
            earlier = sum(1 for s in SUFFIXES for _ in self.folder.glob(f"*_{s}.png"))
            if earlier:
                raise FileExistsError(f"--save-maps {self.folder} already holds {earlier} maps of an earlier run; "
                                      "choose an empty folder, or pass --force to write over them")
        self.folder.mkdir(parents=True, exist_ok=True)
        probe = self.folder / f".bsn-run-{os.getpid()}.probe"   # a read-only disk refuses now, not at the first frame
        probe.write_bytes(b"")
        probe.unlink()
        self.written = 0

    def write(self, name: str, prob: np.ndarray, depth_m: np.ndarray) -> None:
        p8 = np.clip(np.rint(prob * 255.0), 0, 255).astype(np.uint8)
        d16 = np.clip(np.rint(np.nan_to_num(depth_m) * DEPTH_SCALE), 0, 65535).astype(np.uint16)
        for suffix, img in zip(SUFFIXES, (p8, d16), strict=True):
            ok, buf = cv2.imencode(".png", img)
            if not ok:
                raise OSError(f"cannot encode the {suffix} map of {name}")
            atomic_write_bytes(self.folder / f"{name}_{suffix}.png", buf.tobytes())
        self.written += 1


def read_depth_map(path: str | Path) -> np.ndarray:
    """A saved depth map in metres (0 = none)."""
    d = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if d is None or d.dtype != np.uint16:
        raise ValueError(f"{path}: not a 16-bit depth map")
    return d.astype(np.float32) / DEPTH_SCALE
