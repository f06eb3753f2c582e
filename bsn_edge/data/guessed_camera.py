"""The camera a clip is warped with when its user gave no camera file, for training.

``bsn-run`` without a camera file resizes the picture into the model camera (the model camera's
intrinsics, rescaled: :func:`~bsn_edge.calibration.camera_file.assumed_camera`) and takes the
camera to sit as the model camera sits until online calibration has found pitch and yaw. A clip of
the synthetic world, warped with its true camera, never shows a model that picture. This module
says, per clip, which wrong camera to show it instead: half the clips as ``bsn-run`` starts
(:attr:`Guess.AT_START`), half as online calibration leaves them midway (:attr:`Guess.MIDWAY`: the
assumed intrinsics, the pitch and yaw that put the true focus of expansion where the model camera
has it, off by an estimate's error). The draw depends on the clip's folder name only, so a sample
cache of guessed cameras serves every training seed.
"""

from __future__ import annotations

import hashlib
from enum import Enum
from pathlib import Path

import numpy as np

from bsn_edge.calibration.camera_file import Calibration, assumed_camera
from bsn_edge.camera import Intrinsics
from bsn_edge.mounting import ANGLE_LIMIT_DEG, Mounting

MIDWAY_ERROR_DEG = 1.0   # spread (1 sigma) of pitch and yaw halfway through online calibration


class ClipCamera(Enum):
    """Which camera a training clip is warped into the model camera with."""

    OWN = "own"           # its true camera (its camera file)
    GUESSED = "guessed"   # the one a user without a camera file gets (:func:`guessed_camera`)


class GuessedDepth(Enum):
    """What a guessed-camera sample teaches D. A guessed field of view leaves the picture's scale
    unknowable (a longer lens shows a road as a wider one shows a nearer road), so its metric depth
    is not in the picture to learn."""

    METRIC = "metric"           # the true metric depth, as a calibrated sample
    SCALE_FREE = "scale-free"   # the depth up to a factor of the sample's own
    NONE = "none"               # nothing: the sample teaches the blind spots and distillation only


class Guess(Enum):
    """How far ``bsn-run`` has come with a camera it has no file for."""

    AT_START = "at start"   # the assumed camera, sitting as the model camera sits (no road lines found)
    MIDWAY = "midway"       # the assumed intrinsics, pitch and yaw with an estimate's error (the road's
                            # vanishing point, or online calibration midway)


def guess_of(clip: str | Path) -> tuple[Guess, np.random.Generator]:
    """The guess a clip gets, and the generator of its error, both from the clip's folder name."""
    digest = hashlib.sha256(f"guessed camera:{Path(clip).name}".encode()).digest()
    rng = np.random.default_rng(int.from_bytes(digest[:8], "little"))
    return (Guess.AT_START if rng.random() < 0.5 else Guess.MIDWAY), rng


def online_mounting(own: Calibration, assumed: Intrinsics, roll_deg: float = 0.0) -> Mounting:
    """The pitch and yaw online calibration converges to with the ``assumed`` intrinsics: those that
    put the true focus of expansion (the car's forward axis in the true camera) where a camera with
    the assumed intrinsics would see it. Lens distortion is left out: at the focus of expansion,
    near the picture's centre, it moves little. The true height is kept (it changes no picture)."""
    true, mounting = own.intrinsics, own.mounting
    if mounting is None:
        raise ValueError("the camera file gives no mounting: no online calibration to imitate")
    forward = mounting.rotation() @ np.array([0.0, 0.0, 1.0])
    pixel = true.K @ (forward / forward[2])
    seen = np.linalg.solve(assumed.K, pixel)
    return Mounting.from_forward(seen, mounting.height_m, roll_deg)


def guessed_camera(clip: str | Path, own: Calibration, width: int, height: int, model: Intrinsics,
                   model_mounting: Mounting) -> tuple[Calibration, Guess]:
    """The wrong camera clip ``clip`` (frames of ``width`` x ``height``, true camera ``own`` with its
    mounting) is shown with, and which guess it is."""
    if own.mounting is None:
        raise ValueError(f"{clip}: its camera has no mounting to guess from")
    kind, rng = guess_of(clip)
    assumed = assumed_camera(model, model_mounting, width, height, own.mounting.height_m)
    if kind is Guess.AT_START:
        return assumed, kind
    m = online_mounting(own, assumed.intrinsics, model_mounting.roll_deg)
    lim = ANGLE_LIMIT_DEG
    pitch, yaw = (float(np.clip(a + rng.normal(0.0, MIDWAY_ERROR_DEG), -lim, lim)) for a in (m.pitch_deg, m.yaw_deg))
    return assumed.with_mounting(Mounting(m.height_m, pitch, yaw, m.roll_deg), method="online, midway"), kind
