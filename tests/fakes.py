"""What the tests share besides fixtures: stand-ins for hardware that fails, inputs made for the runtime
(videos, camera states) and small synthetic worlds."""

from pathlib import Path

import can
import numpy as np
import serial

from bsn_edge import semantics as sm
from bsn_edge.calibration import Calibration
from bsn_edge.camera import look_pose
from bsn_edge.cli.common import CHECKOUT
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.synth import Agents, Boxes, RoadLayout, World
from bsn_edge.synth.boxes import KIND_VEHICLE

SMOKE = str(CHECKOUT / "configs" / "smoke.toml")   # the tests' training config
SHIPPED = DEFAULT_MODEL                                # the shipped default model


class SimClock:
    """Time that moves only when a heartbeat waits on it; its wait says stop past ``until``."""

    def __init__(self, until: float, start: float = 100.0) -> None:
        self.now, self.until = start, start + until

    def __call__(self) -> float:
        return self.now

    def wait(self, seconds: float) -> bool:
        self.now += seconds
        return self.now >= self.until


# A deadline for a real process on a machine that may be busy (2 cores, load 8-18 from other work): it
# catches a hang, not a slow second. What the product promises on an idle machine (a signal ends a run
# within a second, DEGRADED within a second of an output sticking) is measured there, not asserted here.
BUSY_S = 10.0


class StepClock:
    """A processing clock that moves ``step_s`` each time it is read, whatever the machine does: a run on it
    is never late, so its states and alerts are the same on a busy machine as on an idle one. Thread-safe
    (the feeder and the sinks read it too)."""

    def __init__(self, step_s: float = 1e-4) -> None:
        import threading

        self.now, self.step_s, self._lock = 0.0, step_s, threading.Lock()

    def __call__(self) -> float:
        with self._lock:
            self.now += self.step_s
            return self.now


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


def noise_video(path, frames: int, width: int, height: int, fps: float = 25.0, seed: int = 0):
    """An MPEG-4 file of ``frames`` frames of uniform noise (nothing to calibrate on, everything to decode)."""
    import cv2
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (width, height))
    rng = np.random.default_rng(seed)
    for _ in range(frames):
        w.write(rng.integers(0, 256, (height, width, 3), dtype=np.uint8))
    w.release()
    return path


def mounted(engine, clip):
    """The runtime's camera for the clip's own camera file (mounting known: no online calibration)."""
    from bsn_edge.runtime.camera_state import CameraState

    return CameraState(engine.card, Calibration.read(clip / "calibration.json"))


def ego_pose(x: float = 1.6, y: float = 0.0, pitch: float = 0.02) -> np.ndarray:
    """Camera 1.5 m up, in the right lane, looking along +y."""
    return look_pose(np.array([x, y, 1.5]), np.pi / 2, pitch)


def car(x0, y0, x1, y1, h=1.5) -> Boxes:
    return Boxes.make([(x0, y0, 0.0)], [(x1, y1, h)], sm.CAR, KIND_VEHICLE, (0.5, 0.5, 0.5))


def world_with(layout: RoadLayout, boxes: Boxes) -> World:
    return World(layout, boxes, Agents.empty())


def full_disk_for(path, monkeypatch, module=None) -> None:
    """Writing ``path`` through ``module``'s ``atomic_write_bytes`` (the project's one whole-file writer, as
    ``module`` imported it; default ``bsn_edge.sequence.images``) fails as on a full disk: checked writable
    before the run, it fills up by the time it is written."""
    import errno

    if module is None:
        from bsn_edge.sequence import images as module
    real = module.atomic_write_bytes

    def write(target, data, *a, **k):
        if str(target) == str(path):
            raise OSError(errno.ENOSPC, "No space left on device", str(target))
        return real(target, data, *a, **k)

    monkeypatch.setattr(module, "atomic_write_bytes", write)
