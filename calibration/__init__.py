"""Camera intrinsics and quantization calibration sets."""

from bsn_edge.calibration.frames import load_frames

__all__ = ["load_frames"]
