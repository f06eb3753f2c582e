"""The sequence folder: one driving clip on disk, the format every stage reads and writes.

See the README's "Data formats" section for the layout.
"""

from bsn_edge.sequence.images import (
    atomic_write,
    atomic_write_bytes,
    read_depth,
    read_mask,
    torn_writes,
    write_depth,
    write_image,
    write_mask,
)
from bsn_edge.sequence.meta import SequenceMeta
from bsn_edge.sequence.poses import (
    read_kitti_poses,
    read_poses,
    read_tum_poses,
    write_kitti_poses,
    write_tum_poses,
)

__all__ = [
    "SequenceMeta",
    "atomic_write",
    "atomic_write_bytes",
    "read_depth",
    "read_kitti_poses",
    "read_mask",
    "read_poses",
    "read_tum_poses",
    "torn_writes",
    "write_depth",
    "write_image",
    "write_kitti_poses",
    "write_mask",
    "write_tum_poses",
]
