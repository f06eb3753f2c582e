"""Camera intrinsics (chessboard calibration) and quantization calibration sets."""

from bsn_edge.calibration.chessboard import Calibration, calibrate
from bsn_edge.calibration.frames import load_frames

__all__ = ["Calibration", "calibrate", "load_frames"]
