"""Cameras: intrinsics and lens distortion from chessboard views, the mounting from driving
video, and the camera file that carries them."""

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.calibration.chessboard import calibrate

__all__ = ["Calibration", "calibrate"]
