"""Where a clip's depth, segmentation and poses come from.

Each source is named by a spec string on the command line:

- depth: ``files`` (the sequence's ``depth/``) or ``onnx:MODEL`` (a monocular depth network,
  aligned to metric scale against sparse landmarks triangulated with the clip's poses);
- segmentation: ``files`` (``semantic/``, Cityscapes trainIds) or ``onnx:MODEL``;
- poses: ``files`` (``poses.txt``, KITTI), a trajectory file (KITTI or TUM), or ``vo``
  (the built-in monocular visual odometry).
"""

from bsn_edge.labels.sources.base import ClipData, DepthSource, SegSource
from bsn_edge.labels.sources.files import FilesDepth, FilesSeg, frame_count, load_poses

__all__ = ["ClipData", "DepthSource", "FilesDepth", "FilesSeg", "SegSource", "frame_count", "load_poses"]
