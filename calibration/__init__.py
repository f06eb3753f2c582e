"""Camera intrinsics and lens distortion from chessboard views, and the calibration file."""

from bsn_edge.calibration.chessboard import Calibration, calibrate

__all__ = ["Calibration", "calibrate"]
