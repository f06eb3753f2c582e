"""The camera file: one JSON that describes a user's camera (or a synthetic clip's).

Intrinsics and lens distortion (from ``bsn-calibrate``'s chessboard step) plus, once known, the
mounting (from ``bsn-calibrate --mount`` or ``bsn-run``'s online calibration): height above the
road and the optical axis's pitch, yaw and roll. ``bsn-run --calib``, ``bsn-label --calib`` and
the training data loader read it; this class alone writes and reads it.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from bsn_edge.camera import Intrinsics
from bsn_edge.fields import number
from bsn_edge.model_frame import ModelFrame
from bsn_edge.mounting import Mounting
from bsn_edge.sequence.images import atomic_write_bytes


@dataclass(frozen=True)
class Calibration:
    """A camera: intrinsics at ``width`` x ``height``, distortion, and its mounting when known.

    ``mounting_report`` says where the mounting came from (method, spread over the clip, frames).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: tuple[float, ...] = ()          # OpenCV order k1 k2 p1 p2 k3
    rms_px: float = 0.0
    used: tuple[str, ...] = ()
    skipped: tuple[dict, ...] = field(default_factory=tuple)
    board: tuple[int, int] = (9, 6)
    square_m: float = 0.025
    mounting: Mounting | None = None
    mounting_report: dict[str, Any] = field(default_factory=dict)
    # how fx fy cx cy were found: "chessboard", "field of view: 60 degrees across"; "" when given
    intrinsics_method: str = ""

    def __post_init__(self) -> None:
        self.intrinsics  # noqa: B018 - validates
        if len(self.dist) not in (0, 4, 5, 8, 12, 14):
            raise ValueError(f"dist must hold 0, 4, 5, 8, 12 or 14 OpenCV coefficients, got {len(self.dist)}")

    @classmethod
    def of(cls, intrinsics: Intrinsics, dist: tuple[float, ...] = (), mounting: Mounting | None = None,
           **report: Any) -> Calibration:
        """A camera file for a camera known some other way (a synthetic clip, a dataset's calibration)."""
        k = intrinsics
        return cls(k.fx, k.fy, k.cx, k.cy, k.width, k.height, tuple(float(d) for d in dist), mounting=mounting,
                   mounting_report=dict(report))

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics(self.fx, self.fy, self.cx, self.cy, self.width, self.height)

    @property
    def has_distortion(self) -> bool:
        return any(abs(d) > 1e-9 for d in self.dist)

    def with_mounting(self, mounting: Mounting, **report: Any) -> Calibration:
        return replace(self, mounting=mounting, mounting_report=dict(report))

    def model_frame(self, width: int, height: int, model: Intrinsics, model_mounting: Mounting,
                    mounting: Mounting | None = None) -> ModelFrame:
        """The warp from this camera's frames of ``width`` x ``height`` into the model camera.
        ``mounting`` overrides the file's (online calibration); without either, the camera is taken
        to sit as the model camera does."""
        m = mounting or self.mounting or model_mounting
        # distortion coefficients act on normalised coordinates, so they hold at any frame size
        return ModelFrame(self.intrinsics.scaled(width, height), self.dist, m, model, model_mounting)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["mounting"] = None if self.mounting is None else self.mounting.to_dict()
        return d

    def write(self, path: str | os.PathLike) -> None:
        atomic_write_bytes(path, (json.dumps(self.to_dict(), indent=2) + "\n").encode())

    @classmethod
    def read(cls, path: str | os.PathLike) -> Calibration:
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"calibration file {p} not found")
        try:
            d = json.loads(p.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise ValueError(f"{p}: not a camera file (not JSON: {e})") from None
        if not isinstance(d, dict):
            raise ValueError(f"{p}: not a camera file (expected a JSON object; bsn-calibrate writes one)")
        known = {f.name for f in fields(cls)}     # fields of other versions are left out, not guessed at
        try:
            intrinsic = {k: number(d, k, str(p)) for k in ("fx", "fy", "cx", "cy")}
            size = {k: number(d, k, str(p), int) for k in ("width", "height")}
            m = d.get("mounting")
            rest = {k: v for k, v in d.items() if k in known and k not in (*intrinsic, *size)}
            return cls(**{**rest, **intrinsic, **size, "dist": tuple(d.get("dist", ())),
                          "used": tuple(d.get("used", ())), "skipped": tuple(d.get("skipped", ())),
                          "board": tuple(d.get("board", (9, 6))),
                          "mounting": None if m is None else Mounting.from_dict(m, f"{p}: mounting"),
                          "mounting_report": dict(d.get("mounting_report") or {})})
        except TypeError as e:
            raise ValueError(f"{p}: not a camera file ({e})") from None
        except ValueError as e:
            msg = str(e)
            raise ValueError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


def clip_camera(path: str | os.PathLike, fallback_mounting: Mounting) -> Calibration:
    """A sequence folder's camera: its camera file (``calibration.json``), else its meta's
    intrinsics; sitting at ``fallback_mounting`` when the file gives no mounting (clips made before
    cameras were recorded came from the model camera)."""
    from bsn_edge.sequence.folder import SequenceFolder
    from bsn_edge.sequence.meta import SequenceMeta

    seq = SequenceFolder(path)
    if seq.calibration_path.is_file():
        cal = Calibration.read(seq.calibration_path)
        return cal if cal.mounting is not None else cal.with_mounting(fallback_mounting, method="assumed")
    return Calibration.of(SequenceMeta.read(path).intrinsics, (), fallback_mounting, method="assumed")
