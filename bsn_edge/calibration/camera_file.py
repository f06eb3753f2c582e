"""The camera file: one JSON that describes a user's camera (or a synthetic clip's).

Intrinsics and lens distortion (from ``bsn-calibrate``'s chessboard step) plus, once known, the
mounting (from ``bsn-calibrate --mount`` or ``bsn-run``'s online calibration): height above the
road and the optical axis's pitch, yaw and roll. ``bsn-run --calib``, ``bsn-label --calib`` and
the training data loader read it; this class alone writes and reads it.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.calibration.hood import Hood
from bsn_edge.camera import Intrinsics
from bsn_edge.fields import read_json_object
from bsn_edge.model_frame import ModelFrame
from bsn_edge.mounting import Mounting
from bsn_edge.sequence.images import atomic_write_bytes


@dataclass(frozen=True)
class Calibration:
    """A camera: intrinsics at ``width`` x ``height``, distortion, and its mounting when known.

    ``mounting_report`` says where the mounting came from (method, spread over the clip, frames).
    """

    intrinsics: Intrinsics                # written flat in the file: fx, fy, cx, cy, width, height
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
    # the car's own hood in view, when it was looked for (bsn-calibrate --mount, bsn-run's first seconds);
    # written only when known, so files made before it are read and written unchanged
    hood: Hood | None = None

    def __post_init__(self) -> None:
        if len(self.dist) not in (0, 4, 5, 8, 12, 14):
            raise ValueError(f"dist must hold 0, 4, 5, 8, 12 or 14 OpenCV coefficients, got {len(self.dist)}")
        check_physical(self.intrinsics, self.dist)

    @classmethod
    def of(cls, intrinsics: Intrinsics, dist: tuple[float, ...] = (), mounting: Mounting | None = None,
           **report: Any) -> Calibration:
        """A camera file for a camera known some other way (a synthetic clip, a dataset's calibration)."""
        return cls(intrinsics, tuple(float(d) for d in dist), mounting=mounting, mounting_report=dict(report))

    @property
    def has_distortion(self) -> bool:
        return any(abs(d) > 1e-9 for d in self.dist)

    def with_mounting(self, mounting: Mounting, **report: Any) -> Calibration:
        return replace(self, mounting=mounting, mounting_report=dict(report))

    def with_hood(self, hood: Hood) -> Calibration:
        return replace(self, hood=hood)

    def fit_to(self, width: int, height: int, where: str = "camera file") -> str:
        """Whether this camera file describes frames of ``width`` x ``height``: "" when its size is theirs,
        a note when they have its aspect (its intrinsics are rescaled, as a resized video's are);
        ``ValueError`` naming both sizes when the aspect differs (another camera, or a crop)."""
        k = self.intrinsics
        if (width, height) == (k.width, k.height):
            return ""
        mine, theirs = k.width / k.height, width / height
        if abs(theirs / mine - 1.0) > ASPECT_TOLERANCE:
            raise ValueError(f"{where}: width x height {k.width}x{k.height} (aspect {mine:.3f}), but the "
                             f"source's frames are {width}x{height} (aspect {theirs:.3f}): the file describes "
                             f"another camera or another crop (aspects must agree within "
                             f"{100 * ASPECT_TOLERANCE:g} %); calibrate this one with bsn-calibrate")
        return (f"{where} is for {k.width}x{k.height} frames, the source's are {width}x{height}: the same "
                "aspect, its intrinsics rescaled")

    def model_frame(self, width: int, height: int, model: Intrinsics, model_mounting: Mounting,
                    mounting: Mounting | None = None) -> ModelFrame:
        """The warp from this camera's frames of ``width`` x ``height`` into the model camera.
        ``mounting`` overrides the file's (online calibration); without either, the camera is taken
        to sit as the model camera does."""
        m = mounting or self.mounting or model_mounting
        blocked = self.hood.mask(width, height) if self.hood is not None and self.hood.found else None
        # distortion coefficients act on normalised coordinates, so they hold at any frame size
        return ModelFrame(self.intrinsics.scaled(width, height), self.dist, m, model, model_mounting, blocked)

    def to_dict(self) -> dict[str, Any]:
        """The file's fields, the intrinsics flat at the top (``fx``, ``fy``, ``cx``, ``cy``, ``width``,
        ``height``), as camera files have always been written; the chessboard's (``board``, ``square_m``,
        ``rms_px``, ``used``, ``skipped``) only when one measured the intrinsics."""
        d = asdict(self)
        d = {**d.pop("intrinsics"), **d}
        if not self.used:         # no chessboard measured these intrinsics: nothing of one is written
            for k in ("rms_px", "used", "skipped", "board", "square_m"):
                d.pop(k)
        d["mounting"] = None if self.mounting is None else self.mounting.to_dict()
        if self.hood is None:
            d.pop("hood")
        else:
            d["hood"] = self.hood.to_dict()
        return d

    def write(self, path: str | os.PathLike) -> None:
        atomic_write_bytes(path, (json.dumps(self.to_dict(), indent=2) + "\n").encode())

    @classmethod
    def read(cls, path: str | os.PathLike) -> Calibration:
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"calibration file {p} not found")
        d = read_json_object(p, "not a camera file")
        known = {f.name for f in fields(cls)}     # fields of other versions are left out, not guessed at
        lens = ("fx", "fy", "cx", "cy", "width", "height")
        if not any(k in d for k in lens):
            has = ", ".join(sorted(k for k in d if k in known))
            raise ValueError(f"{p}: holds no lens ({', '.join(lens)})"
                             + (f", only {has}" if has else ", nor anything else a camera file holds")
                             + ". A camera file starts from "
                             "its lens: bsn-calibrate VIDEO --hfov DEG --out CALIB.json for a lens known by its "
                             "field of view (or from a chessboard's pictures); bsn-calibrate --mount then adds the "
                             "mounting and the hood to it")
        try:
            m = d.get("mounting")
            hood = d.get("hood")
            rest = {k: v for k, v in d.items() if k in known and k != "intrinsics"}
            dist = d.get("dist", [])
            if not isinstance(dist, list):
                raise ValueError(f"dist must be a list of numbers (OpenCV's order: k1, k2, p1, p2, k3, ...), "
                                 f"got {json.dumps(dist)}")
            return cls(**{**rest, "intrinsics": Intrinsics.from_dict(d, str(p)), "dist": tuple(dist),
                          "used": tuple(d.get("used", ())), "skipped": tuple(d.get("skipped", ())),
                          "board": tuple(d.get("board", (9, 6))),
                          "mounting": None if m is None else Mounting.from_dict(m, f"{p}: mounting"),
                          "mounting_report": dict(d.get("mounting_report") or {}),
                          "hood": None if hood is None else Hood.from_dict(hood, f"{p}: hood")})
        except (TypeError, OverflowError, RecursionError) as e:     # a 400-digit coefficient, a list 5,000 deep
            raise ValueError(f"{p}: not a camera file ({type(e).__name__}: {str(e)[:80]})") from None
        except ValueError as e:
            msg = str(e)
            raise ValueError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


FOV_RANGE_DEG = (10.0, 170.0)     # horizontal field of view a pinhole model with distortion describes
SIDE_RANGE_PX = (16, 8192)        # width and height: from the smallest test clip to 8K, what cameras make
ASPECT_RANGE = (0.5, 2.0)         # fy / fx: pixels at most twice as tall as wide, or as wide as tall
DIST_LIMIT = 1e3                  # |coefficient|: beyond it no lens, a typo
ASPECT_TOLERANCE = 0.01           # frames whose width / height is the file's within this are the same camera resized
# taking the lens out moves a pixel along its ray from the principal point: to at least half and at most
# twice its distance. The Udacity dashcam's corners go to 1.1 times theirs, a strong barrel on a 70-degree
# pinhole to 1.5; dist [0, 999, 0, 0, 0] on a 70-degree pinhole squeezes its picture's edge to 0.28
LENS_ZOOM_RANGE = (0.5, 2.0)
# the share of the picture a lens undistorts that must have a real pixel behind it: a quarter, what the
# zoom range's 0.5 leaves of it (a barrel keeps all of it)
LENS_REAL_SHARE = 0.25
WARP_GRID = 97                    # points a side over which the lens's warp is judged
# what the terms beyond the radial ones (decentring p1 p2, thin prism s1-s4, sensor tilt) may move a pixel, as a
# share of the half diagonal: real lenses' decentring is under 1 %
LENS_SKEW_LIMIT = 0.1
RADIAL_TERMS = (0, 1, 4, 5, 6, 7)  # k1 k2 k3 k4 k5 k6 in OpenCV's order


def check_physical(k: Intrinsics, dist: tuple[float, ...]) -> None:
    """A camera that can exist: ValueError naming the field and its limit otherwise.

    The field of view across within :data:`FOV_RANGE_DEG`, ``fy / fx`` within :data:`ASPECT_RANGE`,
    the principal point inside the image, every distortion coefficient finite and within
    :data:`DIST_LIMIT`, and the radial distortion monotonic out to the image's corners (a lens model
    that folds back maps two directions onto one pixel: no warp can undo it)."""
    lo_px, hi_px = SIDE_RANGE_PX
    if not (lo_px <= k.width <= hi_px and lo_px <= k.height <= hi_px):
        raise ValueError(f"width x height {k.width}x{k.height}: a camera file describes {lo_px} to {hi_px} pixels "
                         "a side")
    hfov = math.degrees(2 * math.atan(k.width / (2 * k.fx)))
    lo, hi = FOV_RANGE_DEG
    if not lo <= hfov <= hi:
        raise ValueError(f"fx = {k.fx:g} gives a field of view of {hfov:.1f} degrees across {k.width} pixels; "
                         f"a camera file describes {lo:g} to {hi:g} degrees")
    if not ASPECT_RANGE[0] <= k.fy / k.fx <= ASPECT_RANGE[1]:
        raise ValueError(f"fy / fx = {k.fy / k.fx:.3g}; pixels of a camera file are within {ASPECT_RANGE[0]:g} to "
                         f"{ASPECT_RANGE[1]:g} of square")
    if not (0 < k.cx < k.width and 0 < k.cy < k.height):
        raise ValueError(f"the principal point (cx {k.cx:g}, cy {k.cy:g}) lies outside the {k.width}x{k.height} "
                         f"image (width x height)")
    if not all(isinstance(d, int | float) and not isinstance(d, bool) and math.isfinite(d) and abs(d) <= DIST_LIMIT
               for d in dist):
        raise ValueError(f"dist must hold finite numbers within +-{DIST_LIMIT:g}, got {list(dist)}")
    if dist:
        folded = _radial_fold(k, dist)
        if folded is not None:
            raise ValueError(f"dist: the radial distortion folds back {folded} (not monotonic out to the image's "
                             f"corners): no camera images that way")
        moved = _undistortion_fault(k, dist) or _warp_fault(k, dist)
        if moved is not None:
            raise ValueError(f"dist: taking the lens out {moved}: no camera images that way")


def _border(k: Intrinsics, per_side: int = 64) -> dict[str, np.ndarray]:
    """Points along each side of the picture, in order: side -> [N, 2] pixel coordinates."""
    w, h, t = k.width, k.height, np.linspace(0.0, 1.0, per_side)
    return {"top": np.stack([t * w, 0 * t], -1), "right": np.stack([w + 0 * t, t * h], -1),
            "bottom": np.stack([t * w, h + 0 * t], -1), "left": np.stack([0 * t, t * h], -1)}


def _undistortion_fault(k: Intrinsics, dist: tuple[float, ...]) -> str | None:
    """What is wrong with taking the lens out over the picture's border, or None. Radially (exactly, on
    the radial polynomial, which :func:`_radial_fold` has found monotonic): every border pixel moves
    along its ray to within :data:`LENS_ZOOM_RANGE` of its distance from the principal point (the other
    terms: :func:`_warp_fault`)."""
    d = list(dist) + [0.0] * (8 - len(dist))
    k1, k2, _, _, k3, k4, k5, k6 = d[:8]
    border = _border(k)
    pts = np.concatenate(list(border.values()))
    r_d = np.hypot((pts[:, 0] - k.cx) / k.fx, (pts[:, 1] - k.cy) / k.fy)
    r = np.linspace(0.0, 10.0 * float(r_d.max()), 20001)
    r2 = r * r
    curve = r * (1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3) / (1 + k4 * r2 + k5 * r2 ** 2 + k6 * r2 ** 3)
    reach = int(np.argmax(curve >= r_d.max()))
    away = r_d > 1e-6
    zoom = np.interp(r_d[away], curve[:reach + 1], r[:reach + 1]) / r_d[away]
    lo, hi = LENS_ZOOM_RANGE
    if zoom.min() < lo or zoom.max() > hi:
        worst = float(zoom.min() if zoom.min() < lo else zoom.max())
        return (f"moves the picture's edge to {worst:.2f} times its distance from the principal point (a lens "
                f"that exists: {lo:g} to {hi:g} times)")
    return None


def _warp_fault(k: Intrinsics, dist: tuple[float, ...]) -> str | None:
    """What is wrong with the lens's warp, or None: judged on the map the warps sample with (the lens
    model run forwards, as ``cv2.initUndistortRectifyMap`` runs it, tangential, thin-prism and tilt terms
    included: no solver that may not converge). Over a grid of the picture the lens undistorted sees,
    every source pixel must be finite, the terms beyond the radial ones may move it by at most
    :data:`LENS_SKEW_LIMIT` of the half diagonal, at least :data:`LENS_REAL_SHARE` of it must have a real pixel
    behind it, and where it does the map must keep the order of rows and columns (a fold shows one place
    twice)."""
    n = WARP_GRID
    u, v = np.meshgrid(np.linspace(0.0, k.width, n), np.linspace(0.0, k.height, n))
    rays = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u)], -1).reshape(-1, 1, 3)
    with np.errstate(all="ignore"):
        src, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), k.K, np.asarray(dist, np.float64))
    src = src.reshape(n, n, 2)
    if not np.isfinite(src).all():
        return "sends part of the picture to infinity"
    radial = np.zeros(len(dist))
    for i in RADIAL_TERMS:
        if i < len(dist):
            radial[i] = dist[i]
    with np.errstate(all="ignore"):
        only_radial, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), k.K, radial)
    skew = float(np.max(np.hypot(*(src - only_radial.reshape(n, n, 2)).transpose(2, 0, 1))))
    if not skew <= LENS_SKEW_LIMIT * math.hypot(k.width, k.height) / 2:
        return (f"moves the picture by up to {skew:.0f} pixels beyond its radial distortion (decentring, thin "
                f"prism, tilt; a lens that exists: at most {100 * LENS_SKEW_LIMIT:.0f} % of the half diagonal)")
    inside = (src[..., 0] >= 0) & (src[..., 0] <= k.width) & (src[..., 1] >= 0) & (src[..., 1] <= k.height)
    share = float(inside.mean())
    if share < LENS_REAL_SHARE:
        return (f"leaves real pixels behind only {100 * share:.0f} % of the picture it undistorts (a lens that "
                f"exists: at least {100 * LENS_REAL_SHARE:.0f} %)")
    across = inside[:, 1:] & inside[:, :-1]
    down = inside[1:, :] & inside[:-1, :]
    if np.any(np.diff(src[..., 0], axis=1)[across] <= 0) or np.any(np.diff(src[..., 1], axis=0)[down] <= 0):
        return "folds the picture back on itself"
    return None


def _radial_fold(k: Intrinsics, dist: tuple[float, ...]) -> str | None:
    """Where the radial distortion stops growing before it reaches the image's corners, or None."""
    d = list(dist) + [0.0] * (8 - len(dist))
    k1, k2, _, _, k3, k4, k5, k6 = d[:8]
    corner = max(math.hypot((u - k.cx) / k.fx, (v - k.cy) / k.fy) for u in (0, k.width) for v in (0, k.height))
    r = np.linspace(0.0, 10.0 * corner, 4001)
    r2 = r * r
    den = 1 + k4 * r2 + k5 * r2 ** 2 + k6 * r2 ** 3
    with np.errstate(all="ignore"):
        rd = r * (1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3) / den
    reach = np.nonzero(rd >= corner)[0]
    end = int(reach[0]) if len(reach) else len(r) - 1
    steps = np.diff(rd[:end + 1])
    if not np.all(np.isfinite(rd[:end + 1])) or np.any(den[:end + 1] <= 0):
        return "into a pole"
    if len(steps) and np.any(steps <= 0):
        at = float(r[int(np.argmax(steps <= 0))])
        return f"at {at:.2f} (normalised radius; the corners lie at {corner:.2f})"
    if not len(reach):
        return f"short of the corners (it never reaches {corner:.2f})"
    return None


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


def assumed_mounting(model_mounting: Mounting, height_m: float | None = None) -> Mounting:
    """How ``bsn-run`` takes a camera to sit until online calibration has found its mounting: as the
    model camera sits, at ``height_m`` when that is known."""
    m = model_mounting
    return Mounting(height_m or m.height_m, m.pitch_deg, m.yaw_deg, m.roll_deg)


def assumed_camera(model: Intrinsics, model_mounting: Mounting, width: int, height: int,
                   height_m: float | None = None) -> Calibration:
    """The camera ``bsn-run`` takes for frames of ``width`` x ``height`` that come with no camera
    file: the model camera's intrinsics rescaled to the frame (the picture is only resized), no lens,
    sitting as :func:`assumed_mounting` says."""
    cal = Calibration.of(model.scaled(width, height), (), assumed_mounting(model_mounting, height_m),
                         method="assumed: as the model camera sits")
    return replace(cal, intrinsics_method="assumed: the model camera's, rescaled (no camera file)")
