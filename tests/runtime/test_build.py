"""The one builder of a run (bsn_edge.runtime.build): what bsn-run's command line asks for, built and checked."""

import pytest

from bsn_edge.runtime.build import RunRequest, build_run
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.settings import RuntimeConfig


def test_a_request_with_a_camera_file_builds_a_calibrated_camera_on_the_sources_frames(setup):
    model, clip = setup
    said: list[str] = []
    built = build_run(RunRequest(source=str(clip / "video.mp4"), model=str(model),
                                 calib=str(clip / "calibration.json")), RuntimeConfig(), say=said.append)
    try:
        assert isinstance(built.camera, CameraState) and not built.camera.calibrating
        assert built.source.size == (192, 96) and built.maps is None and built.engine.authentic
        assert not any(s.startswith("warning") for s in said), said
    finally:
        built.source.close()


def test_a_camera_file_that_does_not_fit_the_frames_is_refused_naming_it(setup, tmp_path):
    model, clip = setup
    text = (clip / "calibration.json").read_text()
    wrong = tmp_path / "wrong.json"
    wrong.write_text(text.replace('"height": 96', '"height": 400'))
    with pytest.raises(ValueError, match="--calib"):
        build_run(RunRequest(source=str(clip / "video.mp4"), model=str(model), calib=str(wrong)), RuntimeConfig())
