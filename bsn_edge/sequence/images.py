"""Image files of a sequence: RGB, 16-bit depth (metres x 256), 8-bit masks; atomic writes."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np


def _read_umask() -> int:
    old = os.umask(0)
    os.umask(old)
    return old


# read once, at import: os.umask cannot be queried without setting it, which is not thread-safe
_FILE_MODE = 0o666 & ~_read_umask()
DEPTH_SCALE = 256.0  # KITTI convention: uint16 value = metres x 256, 0 = no depth
MAX_DEPTH_M = 65535 / DEPTH_SCALE
PNG_FAST = [cv2.IMWRITE_PNG_COMPRESSION, 1]


def _temp_affixes(path: Path) -> tuple[str, str]:
    return f".{path.name}.", ".tmp"


def atomic_write(path: str | os.PathLike, write: Callable[[BinaryIO], object], durable: bool = False) -> None:
    """Write ``path`` through a temporary file, filled by ``write(file)``, and a rename, so readers
    never see a half-written file and a write that fails leaves nothing behind (a killed process can
    leave its temporary file: :func:`torn_writes` finds it). ``durable`` also fsyncs the data
    before the rename, so a power cut cannot leave an empty file in its place. A pipe or a device at
    ``path`` is written into as asked, never replaced by a file."""
    path = Path(path)
    if path.exists() and not path.is_file() and not path.is_dir():
        with path.open("wb") as f:
            write(f)
        return
    prefix, suffix = _temp_affixes(path)
    fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            if durable:
                f.flush()
                os.fsync(f.fileno())
        os.chmod(tmp, _FILE_MODE)  # mkstemp makes files private; outputs are ordinary files
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes, durable: bool = False) -> None:
    """:func:`atomic_write` of ``data``."""
    atomic_write(path, lambda f: f.write(data), durable)


def torn_writes(path: str | os.PathLike) -> list[Path]:
    """The temporary files that :func:`atomic_write` to ``path`` left when its process was
    killed mid-write (never renamed into place, so never read as ``path``). A write in progress
    looks the same: only the folder's one writer may remove them."""
    path = Path(path)
    prefix, suffix = _temp_affixes(path)
    if not path.parent.is_dir():
        return []
    return sorted(p for p in path.parent.iterdir()
                  if p.name.startswith(prefix) and p.name.endswith(suffix) and len(p.name) > len(prefix + suffix))


def write_image(path: str | os.PathLike, image: np.ndarray, durable: bool = False) -> None:
    """Atomically write an image (``durable``: fsynced first); the format follows the extension."""
    ext = Path(path).suffix or ".png"
    params = PNG_FAST if ext.lower() == ".png" else []
    ok, buf = cv2.imencode(ext, image, params)
    if not ok:
        raise OSError(f"could not encode image for {path}")
    atomic_write_bytes(path, buf.tobytes(), durable)


def read_image(path: str | os.PathLike, flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """An image file as OpenCV reads it with ``flags``; ``FileNotFoundError`` naming it when it cannot be read."""
    img = cv2.imread(str(path), flags)
    if img is None:
        raise FileNotFoundError(f"cannot read image {path} (missing or not an image)")
    return img


def depth_to_png16(depth_m: np.ndarray) -> np.ndarray:
    """Metric depth to the KITTI uint16 encoding; non-finite or non-positive -> 0 (no depth)."""
    d = np.nan_to_num(depth_m.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    d = np.clip(d, 0.0, MAX_DEPTH_M)
    return np.round(d * DEPTH_SCALE).astype(np.uint16)


def write_depth(path: str | os.PathLike, depth_m: np.ndarray) -> None:
    """Write metric depth as a 16-bit PNG, metres x 256, 0 = no depth."""
    write_image(path, depth_to_png16(depth_m))


def read_depth(path: str | os.PathLike) -> np.ndarray:
    """Read a 16-bit depth PNG into float32 metres (0 = no depth)."""
    raw = read_image(path, cv2.IMREAD_UNCHANGED)
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise ValueError(f"{path}: depth must be a single-channel 16-bit PNG, got {raw.dtype} {raw.shape}")
    return raw.astype(np.float32) / DEPTH_SCALE


def write_mask(path: str | os.PathLike, mask: np.ndarray, durable: bool = False) -> None:
    """Write a boolean mask as an 8-bit PNG of 0 / 255."""
    write_image(path, np.where(mask, 255, 0).astype(np.uint8), durable)


def read_mask(path: str | os.PathLike) -> np.ndarray:
    """Read an 8-bit 0 / 255 mask PNG into a boolean array."""
    raw = read_image(path, cv2.IMREAD_GRAYSCALE)
    return raw > 127
