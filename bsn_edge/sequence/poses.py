"""Camera trajectories: KITTI odometry (3x4 row-major per line) and TUM (``t tx ty tz qx qy qz qw``).

Poses are camera-to-world ``T_wc`` 4x4 matrices, shape ``[N, 4, 4]``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from bsn_edge.sequence.images import atomic_write_bytes


def _number_lines(path: str | os.PathLike, kind: str, count: int, fields: str) -> Iterator[list[float]]:
    """The numbers of every line of a pose file but blank and ``#`` lines; a line that is not
    ``count`` numbers is a ``ValueError`` naming the file and the line."""
    for lineno, line in enumerate(Path(path).read_text().splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            vals = [float(v) for v in line.split()]
        except ValueError as e:
            raise ValueError(f"{path}:{lineno}: not a number in {kind}: {e}") from None
        if len(vals) != count:
            raise ValueError(f"{path}:{lineno}: a {kind} has {count} numbers{fields}, found {len(vals)}")
        yield vals


def write_kitti_poses(path: str | os.PathLike, poses: np.ndarray) -> None:
    """Write ``[N, 4, 4]`` camera-to-world poses in the KITTI odometry text format."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"poses must be [N, 4, 4], got {poses.shape}")
    lines = [" ".join(f"{v:.9e}" for v in T[:3].reshape(-1)) for T in poses]
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode())


def read_kitti_poses(path: str | os.PathLike) -> np.ndarray:
    """Read a KITTI odometry pose file (12 numbers per line) into ``[N, 4, 4]``."""
    rows = []
    for vals in _number_lines(path, "KITTI pose line", 12, ""):
        T = np.eye(4)
        T[:3] = np.reshape(vals, (3, 4))
        rows.append(T)
    if not rows:
        raise ValueError(f"{path}: no poses found")
    return np.stack(rows)


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """Rotation matrix from a quaternion ``(qx, qy, qz, qw)`` (normalised here)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rot_to_quat(R: np.ndarray) -> np.ndarray:
    """Quaternion ``(qx, qy, qz, qw)`` of a rotation matrix (Shepperd's method, ``qw >= 0``)."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.zeros(4)
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def write_tum_poses(path: str | os.PathLike, stamps: np.ndarray, poses: np.ndarray) -> None:
    """Write a TUM trajectory (``t tx ty tz qx qy qz qw`` per line)."""
    if len(stamps) != len(poses):
        raise ValueError(f"{len(stamps)} timestamps for {len(poses)} poses")
    lines = [" ".join(f"{v:.9f}" for v in (t, *T[:3, 3], *rot_to_quat(T[:3, :3])))
             for t, T in zip(stamps, poses, strict=True)]
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode())


def read_tum_poses(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory; returns ``(timestamps [N], poses [N, 4, 4])``."""
    stamps, poses = [], []
    for vals in _number_lines(path, "TUM line", 8, " (t tx ty tz qx qy qz qw)"):
        T = np.eye(4)
        T[:3, :3] = quat_to_rot(np.array(vals[4:8]))
        T[:3, 3] = vals[1:4]
        stamps.append(vals[0])
        poses.append(T)
    if not poses:
        raise ValueError(f"{path}: no poses found")
    return np.array(stamps), np.stack(poses)


def read_poses(path: str | os.PathLike) -> np.ndarray:
    """Read KITTI or TUM poses, telling them apart by the count of numbers per line."""
    first = next((ln for ln in Path(path).read_text().splitlines()
                  if ln.strip() and not ln.lstrip().startswith("#")), "")
    if len(first.split()) == 8:
        return read_tum_poses(path)[1]
    return read_kitti_poses(path)
