"""A folder whose pictures are not one camera: each picture its own (:mod:`bsn_edge.calibration.folder_cameras`).

Each picture is warped with its own lens (its EXIF record's, else the model camera's field of view
rescaled to it) and the model camera's mounting: nothing one picture shows says how another camera
sits, so no first guess, online calibration or hood search gathers over them. The status stays
CALIBRATING (the mounting is assumed, not measured), as for any camera not yet calibrated.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.calibration.exif import from_exif
from bsn_edge.calibration.folder_cameras import FolderVerdict
from bsn_edge.card import ModelCard
from bsn_edge.runtime.camera_state import CameraState


class PictureCameras(CameraState):
    """The camera of the picture being warped; :meth:`picture` is told each picture before its warp."""

    def __init__(self, card: ModelCard, verdict: FolderVerdict, height_m: float | None = None) -> None:
        super().__init__(card, None, height_m)
        self.verdict = verdict
        self._vanishing = None
        self._hood_finder = None
        self._picture: Path | None = None
        self.lenses = {"exif": 0, "assumed": 0}

    def picture(self, path: Path | None, frame: np.ndarray) -> None:
        """The next frame to warp is the picture ``path``: its own camera from here on."""
        with self._lock:
            if path is not None and path == self._picture:
                return
            self._picture = path
            h, w = frame.shape[:2]
            self.calibration = None if path is None else from_exif(path, w, h)
            self.lenses["exif" if self.calibration is not None else "assumed"] += 1
            self._camera_file = None
            self._frames.clear()

    def observe(self, frame: np.ndarray) -> None:
        """Nothing to learn from a picture about the next one."""

    def _progress(self) -> str:
        return (f"{self.verdict.cameras.value} ({self.verdict.why}): lens from EXIF for {self.lenses['exif']}, "
                f"assumed for {self.lenses['assumed']}; the model camera's mounting assumed for every one")

    def summary(self) -> dict[str, Any]:
        out = super().summary()
        with self._lock:
            out.update(intrinsics="per picture: its EXIF lens, else the model camera's rescaled",
                       cameras=self.verdict.to_dict(), lenses=dict(self.lenses))
        return out
