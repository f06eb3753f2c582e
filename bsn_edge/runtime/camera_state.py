"""The runtime's camera: the warp of each frame into the model camera, and online calibration.

With a camera file that carries a mounting, that mounting is used from the first frame. Without
one, the camera is calibrated online as openpilot's calibration daemon does: frames are warped with
a first guess (the pitch and yaw of the road's vanishing point in the first frames, provisionally from
the first frame it is found in,
:mod:`bsn_edge.calibration.vanishing_point`; else as the model camera sits) while pitch and yaw are
estimated from the focus of expansion of forward driving (:mod:`bsn_edge.calibration.mount_fit`); the
status on the bus says CALIBRATING until the estimate has converged, then the estimate is used (and
saved, when asked). Without a camera file at all the intrinsics are taken as the model camera's,
rescaled to the frame (the picture is only resized; a photo's EXIF lens when the caller read one):
the overlay and summary say so.
"""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.calibration.camera_file import Calibration, assumed_camera, assumed_mounting
from bsn_edge.calibration.hood import Hood, HoodConfig, HoodFinder
from bsn_edge.calibration.mount_fit import MountFitConfig
from bsn_edge.calibration.vanishing_point import VanishingGuess
from bsn_edge.card import ModelCard
from bsn_edge.model_frame import ModelFrame
from bsn_edge.mounting import Mounting
from bsn_edge.runtime.calibrator import OnlineCalibrator
from bsn_edge.runtime.sinks import SinkFailure
from bsn_edge.runtime.source_config import CalibrationConfig

CAMERA_FILE = "camera file"      # the output --save-calib names, as the summary's sinks name it


class CameraState:
    """Owns the model frame of the current frame size; refits online while calibrating.

    Online, about ``CALIBRATE_HZ`` frames a second are fed to the estimator (one in
    ``calibrate_every``; by default chosen from the source's frame rate, :meth:`use_frame_rate`),
    which runs on a thread of its own (:class:`OnlineCalibrator`; ``background=False`` runs it on
    the caller's) at a lower priority (``calibrate_nice``). ``close()`` stops that thread. Frames
    may be warped on one thread (the loop's feeder) while another asks for :meth:`progress` or
    :meth:`summary`: one lock guards the state."""

    CALIBRATE_HZ = CalibrationConfig.frames_per_s     # the vehicle file's calibration.frames_per_s, by default
    # a camera file whose camera shows the model less of its view than this (its hood masked) is refused:
    # blind spots anywhere else could never be seen. A 16:9 lens of 30 degrees across straight ahead still
    # shows 12 % of the model camera's 80 degrees (25 degrees: 8 %); a long lens pitched off the road, none
    MIN_SEEN_SHARE = 0.1

    def __init__(self, card: ModelCard, calibration: Calibration | None = None, height_m: float | None = None,
                 save_to: str | Path | None = None, calibrate_every: int | None = None,
                 background: bool = True, calibrate_nice: int = 10, estimator: MountFitConfig | None = None,
                 calibrate_hz: float | None = None, hood: HoodConfig | None = None,
                 intrinsics_from: str = "camera file") -> None:
        """``estimator`` and ``calibrate_hz``: the online estimator's settings and how many frames a
        second it is fed; ``hood``: how the hood is looked for (the runtime's own unless given:
        benchmarks and tests compare others); ``intrinsics_from``: where ``calibration``'s intrinsics
        came from, for the summary (a picture's EXIF, when there is no camera file)."""
        self.card = card
        self.calibration = calibration
        self.save_to = Path(save_to) if save_to else None
        self.save_failure: SinkFailure | None = None    # the camera file could not be written (a full disk)
        self.intrinsics_from = "assumed: the model camera's, rescaled (no camera file)" if calibration is None \
            else intrinsics_from
        self.height_m = height_m or (calibration.mounting.height_m if calibration and calibration.mounting
                                     else card.mounting.height_m)
        self.height_from = "given" if height_m else ("the camera file's" if calibration and calibration.mounting
                                                     else "the model camera's; --height sets it")
        self.mounting: Mounting | None = calibration.mounting if calibration is not None else None
        if self.mounting is not None and height_m:
            self.mounting = Mounting(height_m, self.mounting.pitch_deg, self.mounting.yaw_deg, self.mounting.roll_deg)
        self.calibrate_every = None if calibrate_every is None else max(1, int(calibrate_every))
        self.background, self.calibrate_nice, self.estimator = background, calibrate_nice, estimator
        self.calibrate_hz = self.CALIBRATE_HZ if calibrate_hz is None else float(calibrate_hz)
        if self.calibrate_hz <= 0:
            raise ValueError(f"calibrate_hz must be positive, got {calibrate_hz}")
        self.calibrate_wait = True
        self.size_note = ""          # the camera file was made for frames of another size, same aspect
        self.report: dict[str, Any] = {"source": "camera file" if self.mounting else "online"}
        self._calibrator: OnlineCalibrator | None = None
        self._frames: dict[tuple[int, int], ModelFrame] = {}
        self._camera_file: tuple[tuple[int, int, Hood | None], Calibration] | None = None
        self._lock = threading.RLock()
        # the hood: the camera file's when it has looked, else looked for in the first seconds
        self.hood: Hood | None = calibration.hood if calibration is not None else None
        self._hood_finder = HoodFinder(hood) if self.hood is None else None
        self._hood_seen = 0
        # until online calibration has converged: pitch and yaw from the road's vanishing point
        self._vanishing = VanishingGuess() if self.mounting is None else None
        self._guess_seen = 0
        self._observed = 0                 # frames seen by observe(): when calibration converged
        self._fps: float | None = None

    @property
    def calibrating(self) -> bool:
        with self._lock:
            return self.mounting is None

    def use_frame_rate(self, fps: float, live: bool = False) -> None:
        """The source's frame rate: online calibration then feeds about ``CALIBRATE_HZ`` frames a second
        (unless ``calibrate_every`` was given). From a ``live`` source the frame path never waits for
        the estimator: a frame it is too busy for is skipped (from a file it waits, so which frames are
        used does not depend on timing)."""
        if self.calibrate_every is None and self._calibrator is None and fps > 0:
            self.calibrate_every = max(1, round(fps / self.calibrate_hz))
        self.calibrate_wait = not live
        self._fps = fps if fps > 0 else None

    def close(self) -> None:
        """Stop online calibration's thread (idempotent)."""
        if self._calibrator is not None:
            self._calibrator.close()

    def camera_file(self, width: int, height: int) -> Calibration:
        """The camera as known now: the camera file (else the assumed camera), with the hood once found.
        Built once per frame size and hood: building one checks its lens, and calibration asks every frame."""
        with self._lock:
            key = (width, height, self.hood)
            if self._camera_file is None or self._camera_file[0] != key:
                cal = self.calibration or assumed_camera(self.card.camera, self.card.mounting, width, height,
                                                         self.height_m)
                cal = cal if self.hood is None or cal.hood is not None else cal.with_hood(self.hood)
                self._camera_file = (key, cal)
            return self._camera_file[1]

    def observe(self, frame: np.ndarray) -> None:
        """Let online calibration see this frame (nothing once the mounting is known): the estimator is
        started on the first frame, fed one frame in ``calibrate_every``, and when it has converged the
        mounting is taken (and the camera file written, when asked). The runtime's frame path calls it
        before :meth:`frame_for`, frame by frame in order. Until the hood is known (from the camera file,
        or found in the frames fed, one in ``calibrate_every``) it is looked for too."""
        self._observed += 1
        if (finder := self._hood_finder) is not None:
            self._look_for_hood(finder, frame)
        if self.calibrating:
            self._look_for_vanishing_point(frame)
            self._calibrate(frame)

    def picture(self, path: Path | None, frame: np.ndarray) -> None:
        """The next frame to warp is the picture ``path`` (None: not a picture). One camera: nothing
        changes (:class:`~bsn_edge.runtime.picture_cameras.PictureCameras` takes each picture's own)."""

    def frame_for(self, frame: np.ndarray) -> ModelFrame:
        """The model frame for this raw frame with the mounting known now (built once per size and
        mounting); it changes nothing (:meth:`observe` is what calibrates)."""
        h, w = frame.shape[:2]
        with self._lock:
            key = (h, w)
            mf = self._frames.get(key)
            if mf is None or mf.mounting != (self.mounting or self._guess):
                mf = self.camera_file(w, h).model_frame(w, h, self.card.camera, self.card.mounting,
                                                        mounting=self.mounting or self._guess)
                self._frames[key] = mf
            return mf

    def check_view(self, width: int, height: int) -> float:
        """The share of the model's view that the camera file's camera shows, for frames of ``width`` x
        ``height`` (its hood masked); ``ValueError`` naming it when under :attr:`MIN_SEEN_SHARE`. A camera
        calibrated online is not judged: it starts from the model camera's own mounting."""
        if self.mounting is None:
            return 1.0
        mf = self.frame_for(np.empty((height, width, 0), np.uint8))
        share = float(mf.seen.mean())
        if share < self.MIN_SEEN_SHARE:
            m = self.mounting
            raise ValueError(f"the camera file's camera (mounted at pitch {m.pitch_deg:+.1f}, yaw {m.yaw_deg:+.1f}, "
                             f"roll {m.roll_deg:+.1f} degrees{', its hood masked' if self.hood is not None else ''}) "
                             f"shows {100 * share:.1f} % of the model's view; at least "
                             f"{100 * self.MIN_SEEN_SHARE:.0f} % is needed, or blind spots could never be seen")
        return share

    def _look_for_hood(self, finder: HoodFinder, frame: np.ndarray) -> None:
        self._hood_seen += 1
        if (self._hood_seen - 1) % (self.calibrate_every or 1):
            return
        finder.add(frame)
        if finder.ready:
            hood = finder.result()
            with self._lock:
                self.hood, self._hood_finder = hood, None
                self._frames.clear()            # the model frames are built again, the hood masked

    def _look_for_vanishing_point(self, frame: np.ndarray) -> None:
        guess = self._vanishing
        self._guess_seen += 1
        if guess is None or guess.done or (self._guess_seen - 1) % (self.calibrate_every or 1):
            return
        h, w = frame.shape[:2]
        cam = self.camera_file(w, h)
        found = guess.look(frame, cam.intrinsics.scaled(w, h), cam.dist)
        with self._lock:
            guess.record(found)

    @property
    def _guess(self) -> Mounting:
        """The mounting while calibrating: the vanishing point's, else the model camera's."""
        assumed = assumed_mounting(self.card.mounting, self.height_m)
        seen = self._vanishing.provisional(assumed) if self._vanishing is not None else None
        return seen or assumed

    def _calibrate(self, frame: np.ndarray) -> None:
        # only the thread that warps frames feeds the estimator; the lock is held for the state it
        # changes, not while the frame is handed over (which may wait for the estimator)
        h, w = frame.shape[:2]
        cam = self.camera_file(w, h)
        if self._calibrator is None:
            self._calibrator = OnlineCalibrator(cam.intrinsics.scaled(w, h), cam.dist, self.height_m,
                                                self.calibrate_every or 1, background=self.background,
                                                nice=self.calibrate_nice, wait=self.calibrate_wait,
                                                cfg=self.estimator)
        self._calibrator.feed(frame)
        m, report = self._calibrator.result()
        with self._lock:
            if report:
                self.report = {"source": "online", **report}
            if self._calibrator.error:          # the estimator failed: say so instead of calibrating for ever
                self.report["error"] = self._calibrator.error
            if m is not None:
                self.mounting = m
                self.report["converged_at"] = {
                    "frame": self._observed,
                    "seconds": None if self._fps is None else round(self._observed / self._fps, 2)}
                if self.save_to is not None:
                    try:
                        cam.with_mounting(m, **report).write(self.save_to)
                        self.report["saved"] = str(self.save_to)
                    except OSError as e:      # an output that failed: the drive goes on, DEGRADED (the loop)
                        self.save_failure = SinkFailure(CAMERA_FILE, self._observed,
                                                        f"{self.save_to}: {e.strerror or e}")
        if m is not None:
            self._calibrator.close()

    def assumed(self) -> str:
        """What the levels are computed with while calibrating, in a line: the camera's height and where it
        came from, its lens (horizontal field of view) and where that came from, and why frame pairs were
        not used ("" before the first frame)."""
        with self._lock:
            if self._camera_file is None:
                return ""
            intr = self._camera_file[1].intrinsics
            report = dict(self.report)
        hfov = 2.0 * math.degrees(math.atan(intr.width / (2.0 * intr.fx)))
        height = f"height {self.height_m:.2f} m ({self.height_from})"
        lens = f"lens {hfov:.1f} deg across: {self.intrinsics_from}"
        rejected = report.get("rejected") or {}
        why = ", ".join(f"{n} {k}" for k, n in sorted(rejected.items(), key=lambda kv: -kv[1]))
        return f"{height}, {lens}" + (f"; frame pairs not used: {why}" if why else "")

    def hood_progress(self) -> str:
        """Where the search for the hood stands, in words ("" once the hood is known)."""
        with self._lock:
            f = self._hood_finder
            if f is None:
                return ""
            return f"still looked for: {len(f.frames)} of the {f.cfg.frames} frames it needs seen (nothing masked)"

    def _hood_summary(self) -> dict[str, Any] | None:
        """The hood as found (or said by the camera file); None while it is still looked for."""
        with self._lock:
            return None if self.hood is None else self.hood.to_dict()

    def progress(self) -> str:
        """Where online calibration stands, in a line: pairs used and the standard errors of pitch and
        yaw against what convergence needs; once converged, the mounting and the frame it converged at
        ("" with a camera file's mounting)."""
        with self._lock:
            return self._progress()

    def _progress(self) -> str:
        if not self.calibrating:
            at, m = self.report.get("converged_at"), self.mounting
            if not at or m is None:
                return ""
            return (f"calibrated: pitch {m.pitch_deg:+.2f} yaw {m.yaw_deg:+.2f} deg, converged at frame "
                    f"{at['frame']}")
        r = self.report or {}
        need = self._calibrator.fit.cfg if self._calibrator is not None else None
        if need is None or not r.get("pairs"):
            seen = self._calibrator.seen if self._calibrator is not None else 0
            return (f"calibrating: {seen} frames seen, no usable frame pair yet (needs forward driving)"
                    + self._meanwhile())
        text = f"calibrating: {r['used']} of {r['pairs']} frame pairs used (needs {need.min_pairs})"
        se = r.get("standard_error_deg")
        if se:
            text += (f", standard error pitch {se['pitch']:.2f} yaw {se['yaw']:.2f} deg "
                     f"(needs {need.max_spread_deg:g})")
        return text + self._meanwhile()

    def _meanwhile(self) -> str:
        g = self._vanishing
        if g is None or not g.looked:
            return ""
        m = g.provisional(assumed_mounting(self.card.mounting, self.height_m))
        if m is None:
            return (f"; meanwhile the camera is taken to sit as the model camera does (the road's vanishing point "
                    f"is {g.state()})")
        if not g.agreed:
            return (f"; meanwhile pitch {m.pitch_deg:+.2f} yaw {m.yaw_deg:+.2f} deg from the road's vanishing point, "
                    f"provisionally ({len(g.found)} of the {g.agree} frames it needs)")
        return (f"; meanwhile pitch {m.pitch_deg:+.2f} yaw {m.yaw_deg:+.2f} deg from the road's vanishing point "
                f"({len(g.found)} of {g.looked} frames agree within {max(g.spread_deg or (0.0,)):.1f} deg)")

    def summary(self) -> dict[str, Any]:
        with self._lock:
            m, report = self.mounting, dict(self.report)
        return {"cameras": {"cameras": "one camera", "why": "one source"}, "intrinsics": self.intrinsics_from,
                "size_note": self.size_note,
                "mounting": None if m is None else m.to_dict(),
                "calibrating": m is None, "calibration": report, "hood": self._hood_summary(),
                "first_guess": self._vanishing.to_dict() if self._vanishing is not None else None,
                "estimator_skipped": self._calibrator.skipped if self._calibrator is not None else 0}
