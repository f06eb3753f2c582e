"""The one way a run is put together: :class:`RunRequest` (what a user asks to run) and :func:`build_run`, which
makes the verified engine, the source, the camera and the maps writer from it and the resolved settings,
each checked before the first frame. ``bsn-run`` parses its command line into a request and calls this.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.runtime.maps import MapWriter
from bsn_edge.runtime.settings import RuntimeConfig
from bsn_edge.runtime.sources import Source


@dataclass(frozen=True)
class RunRequest:
    """What a run is asked to run on: the source (a video, a folder, a camera index, a stream's URL), the
    model and the keys it must be signed by, the camera (a camera file, the camera's height, where online
    calibration saves its file) and the maps written beside the bus."""

    source: str
    model: str | Path = DEFAULT_MODEL
    calib: str | None = None
    height: float | None = None
    save_calib: str | None = None
    save_maps: str | None = None
    force: bool = False               # maps may be written over an earlier run's
    trust: tuple[str, ...] = ()
    allow_unsigned: bool = False
    pace: bool = False                # a file or folder played at its own rate, as a camera delivers it


@dataclass
class Built:
    """A run's pieces, built and checked: the engine, the camera (one camera's state, or each picture's own
    for a folder of several cameras), the source and the maps writer (None without maps)."""

    engine: Engine
    camera: Any                       # CameraState, or PictureCameras for a folder of several cameras
    source: Source
    maps: MapWriter | None


def build_run(request: RunRequest, cfg: RuntimeConfig, say: Callable[[str], Any] = print) -> Built:
    """The run's pieces from ``request`` and the resolved settings ``cfg``; ``say`` is told each warning and
    note (``warning: ...``, ``note: ...``). ``FileNotFoundError``, ``ValueError`` or ``OSError`` names what is
    wrong; a source already opened is closed again."""
    from bsn_edge.calibration.camera_file import Calibration
    from bsn_edge.modelfile.trust import TrustPolicy
    from bsn_edge.mounting import check_height
    from bsn_edge.runtime.sources import open_source

    calibration = Calibration.read(request.calib) if request.calib else None
    if request.height is not None:
        check_height(request.height, "--height")
    maps = MapWriter(request.save_maps, overwrite=request.force) if request.save_maps else None
    engine = Engine(request.model, cfg.engine_threads, cfg.spin,
                    trust=TrustPolicy.default(list(request.trust), request.allow_unsigned))
    if not engine.authentic:
        say(f"warning: {engine.verdict.note}; it runs because of --allow-unsigned, and the status says "
            "Model_Unsigned on every cycle")
    source = open_source(request.source, pace=request.pace, reconnect=cfg.source.reconnect())
    try:
        return Built(engine, _camera(request, cfg, engine, source, calibration, say), source, maps)
    except BaseException:
        source.close()
        raise


def _camera(request: RunRequest, cfg: RuntimeConfig, engine: Engine, source: Source, calibration: Any,
            say: Callable[[str], Any]) -> Any:
    """The camera the frames are warped with: the camera file's, the pictures' own (a folder of several
    cameras), or online calibration's from EXIF or the model camera; ``ValueError`` for frames of a size
    the runtime does not take or a camera file that does not fit them."""
    from bsn_edge.calibration.camera_file import SIDE_RANGE_PX
    from bsn_edge.calibration.exif import from_exif

    if source.size is not None and source.one_camera and not all(
            SIDE_RANGE_PX[0] <= side <= SIDE_RANGE_PX[1] for side in source.size):
        raise ValueError(f"{request.source}: frames of {source.size[0]}x{source.size[1]}: bsn-run takes frames "
                         f"{SIDE_RANGE_PX[0]} to {SIDE_RANGE_PX[1]} pixels on a side")
    if calibration is None and source.cameras is not None and not source.one_camera:
        from bsn_edge.runtime.picture_cameras import PictureCameras
        say(f"note: {source.cameras.cameras.value}: {source.cameras.why}; each is warped with its own lens "
            "(EXIF, else assumed) and the model camera's mounting (pass --calib if they are one camera)")
        return PictureCameras(engine.card, source.cameras, request.height)
    intrinsics_from = "camera file"
    if calibration is None and source.picture is not None and source.size is not None:
        calibration = from_exif(source.picture, *source.size)
        if calibration is not None:
            intrinsics_from = calibration.intrinsics_method
            say(f"note: no camera file: the intrinsics from the {intrinsics_from}; pitch and yaw are calibrated "
                "online")
    camera = CameraState(engine.card, calibration, request.height, request.save_calib,
                         intrinsics_from=intrinsics_from, calibrate_nice=cfg.calibration.nice,
                         calibrate_hz=cfg.calibration.frames_per_s)
    if calibration is not None and source.size is not None:
        try:
            camera.size_note = calibration.fit_to(*source.size, where=f"--calib {request.calib}")
            camera.check_view(*source.size)
        except ValueError as e:
            raise ValueError(str(e) if str(e).startswith("--calib") else f"--calib {request.calib}: {e}") from None
        if camera.size_note:
            say(f"note: {camera.size_note}")
    return camera
