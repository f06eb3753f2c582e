"""Stand-ins for hardware that fails, and inputs made for the runtime tests, shared by the alerts and
runtime tests."""

from pathlib import Path

import can
import serial


class FullBus:
    """A CAN bus whose transmit buffer is always full."""

    def send(self, msg, timeout=None):
        raise can.CanOperationError("Transmit buffer full")

    def shutdown(self):
        pass


class GonePort:
    """A serial port that was unplugged."""

    is_open = True

    def write(self, data):
        raise serial.SerialException("device disconnected")

    def close(self):
        pass


def long_video(clip: Path, out: Path, repeats: int) -> Path:
    """The clip's frames ``repeats`` times over as an MPEG-4 file at 10 frames/s."""
    import cv2

    frames = [cv2.imread(str(p)) for p in sorted((clip / "rgb").glob("*.png"))]
    h, w = frames[0].shape[:2]
    vw = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (w, h))
    for _ in range(repeats):
        for f in frames:
            vw.write(f)
    vw.release()
    return out
