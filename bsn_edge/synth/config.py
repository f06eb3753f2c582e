"""Configuration of one synthetic clip."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from bsn_edge.mounting import REFERENCE_HEIGHT_M
from bsn_edge.synth.style import get_style

CAMERAS = ("vary", "fixed")


@dataclass(frozen=True)
class SynthConfig:
    """Everything that decides a synthetic clip; the same config and seed give the same bytes.

    Densities are multipliers on the style's own (1.0 = the style's default).
    """

    frames: int = 200
    height: int = 256
    width: int = 512
    fps: float = 10.0
    style: str = "town"
    seed: int = 0
    camera: str = "vary"           # "vary": each clip draws its own camera from its seed (synth.rig)
    hfov_deg: float = 80.0         # the camera of "fixed" clips
    camera_height: float = REFERENCE_HEIGHT_M
    roll_deg: float = 0.0          # the roll of "fixed" clips' camera about its optical axis
    bs_range: float = 50.0        # R: blind spots count within this ground distance, metres
    far: float = 250.0            # nothing is rendered beyond this depth
    parked: float = 1.0
    traffic: float = 1.0
    pedestrians: float = 1.0
    lead: float = 0.7             # probability that the clip follows a platoon in its lane (not with traffic 0)
    queue: float = 0.0            # probability that the clip creeps in slow traffic behind a platoon
    sensor_effects: bool = True   # blur, noise, tone curve, vignetting, JPEG (synth.sensor)

    def __post_init__(self) -> None:
        get_style(self.style)
        if self.camera not in CAMERAS:
            raise ValueError(f"camera must be one of {CAMERAS}, got {self.camera!r}")
        if self.frames < 1:
            raise ValueError(f"frames must be >= 1, got {self.frames}")
        if self.height < 16 or self.width < 16:
            raise ValueError(f"image size must be at least 16x16, got {self.height}x{self.width}")
        if not 0.5 <= self.fps <= 120:
            raise ValueError(f"fps must be in [0.5, 120], got {self.fps}")
        if not 20.0 <= self.hfov_deg <= 150.0:
            raise ValueError(f"hfov_deg must be in [20, 150], got {self.hfov_deg}")
        if not -15.0 <= self.roll_deg <= 15.0:
            raise ValueError(f"roll_deg must be in [-15, 15], got {self.roll_deg}")
        if not 0.5 <= self.camera_height <= 4.0:
            raise ValueError(f"camera_height must be in [0.5, 4] m, got {self.camera_height}")
        if not 0 < self.bs_range < self.far:
            raise ValueError(f"need 0 < bs_range < far, got {self.bs_range} and {self.far}")
        if self.far > 255.0:
            raise ValueError(f"far must be <= 255 m (the 16-bit depth format's limit), got {self.far}")
        for name in ("lead", "queue"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} is a probability in [0, 1], got {getattr(self, name)}")
        for name in ("parked", "traffic", "pedestrians"):
            if not 0.0 <= getattr(self, name) <= 5.0:
                raise ValueError(f"{name} density multiplier must be in [0, 5], got {getattr(self, name)}")

    def to_dict(self) -> dict:
        return asdict(self)
