"""bsn-calibrate on rendered chessboards with known intrinsics and distortion, and on real photos."""

import functools
import json

import cv2
import numpy as np
import pytest

from bsn_edge.calibration import Calibration, calibrate
from bsn_edge.camera import Intrinsics
from bsn_edge.cli import calibrate as calib_cli
from bsn_edge.cli.common import REAL_DATA
from bsn_edge.mounting import Mounting

REAL = REAL_DATA / "camera_cal"
K_TRUE = np.array([[520.0, 0, 322.0], [0, 515.0, 236.0], [0, 0, 1]])
DIST_TRUE = np.array([-0.28, 0.09, 0.0005, -0.0003, 0.0])
W, H = 640, 480


@functools.cache
def _rays(ss: int) -> np.ndarray:
    """Every supersampled pixel's ray through the true, distorted camera (the same for every view)."""
    u, v = np.meshgrid((np.arange(W * ss) + 0.5) / ss - 0.5, (np.arange(H * ss) + 0.5) / ss - 0.5)
    pts = np.stack([u.ravel(), v.ravel()], 1).astype(np.float64)[:, None, :]
    und = cv2.undistortPoints(pts, K_TRUE, DIST_TRUE,
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-9)).reshape(-1, 2)
    return np.concatenate([und, np.ones((len(und), 1))], 1)


def render_board(rvec, tvec, cols=9, rows=6, square=0.03, ss=3) -> np.ndarray:
    """A distorted view of a (cols+1)x(rows+1)-square board, 3x3 supersampled."""
    rays = _rays(ss)
    R, _ = cv2.Rodrigues(np.asarray(rvec, float))
    n, p0 = R[:, 2], np.asarray(tvec, float)
    t = (p0 @ n) / (rays @ n)
    X = rays * t[:, None] - p0
    bx, by = X @ R[:, 0], X @ R[:, 1]
    i, j = np.floor(bx / square + 1), np.floor(by / square + 1)
    inside = (i >= 0) & (i <= cols) & (j >= 0) & (j <= rows)
    val = np.where(inside, np.where((i + j) % 2 == 0, 20, 235), 150).astype(np.float32)
    big = val.reshape(H * ss, W * ss)
    return cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA).astype(np.uint8)


@pytest.fixture(scope="module")
def boards(tmp_path_factory):
    root = tmp_path_factory.mktemp("boards")
    rng = np.random.default_rng(0)
    for k in range(14):
        rvec = rng.normal(0, 0.35, 3)
        tvec = [rng.uniform(-0.2, 0.05), rng.uniform(-0.15, 0.0), rng.uniform(0.45, 0.8)]
        cv2.imwrite(str(root / f"view{k:02d}.png"), render_board(rvec, tvec))
    cv2.imwrite(str(root / "blank.png"), np.full((H, W), 128, np.uint8))
    return root


def test_recovers_known_intrinsics_and_distortion(boards):
    cal = calibrate(boards, (9, 6), 0.03)
    # stated tolerances for 12-14 rendered 640x480 views (the renderer's own sampling adds error)
    assert cal.rms_px < 1.0
    k = cal.intrinsics
    assert k.fx == pytest.approx(520.0, rel=0.015) and k.fy == pytest.approx(515.0, rel=0.015)
    assert abs(k.cx - 322.0) < 4 and abs(k.cy - 236.0) < 4
    assert cal.dist[0] == pytest.approx(-0.28, abs=0.04)
    assert "blank.png" in [s["view"] for s in cal.skipped]
    assert all("no complete 9x6 board" in s["reason"] for s in cal.skipped)


def test_cli_writes_a_file_the_runtime_reads(boards, tmp_path, capsys):
    out = tmp_path / "calib.json"
    assert calib_cli.main([str(boards), "--board", "9x6", "--square", "0.03", "--out", str(out)]) == 0
    assert "RMS reprojection error" in capsys.readouterr().out
    cal = Calibration.read(out)
    assert cal.intrinsics.width == W and json.loads(out.read_text())["rms_px"] == cal.rms_px
    img = cv2.imread(str(boards / "view00.png"))
    mf = cal.model_frame(W, H, Intrinsics.from_fov(256, 128, 80.0), Mounting(1.5, 1.5))
    assert mf.to_model(img).shape == (128, 256, 3)
    # rescaling to a model's size happens in one place
    assert cal.intrinsics.scaled(320, 240).fx == pytest.approx(cal.intrinsics.fx / 2)


def test_too_few_boards_and_bad_arguments(tmp_path, capsys):
    (tmp_path / "imgs").mkdir()
    cv2.imwrite(str(tmp_path / "imgs" / "a.png"), np.zeros((50, 50), np.uint8))
    assert calib_cli.main([str(tmp_path / "imgs"), "--out", str(tmp_path / "c.json")]) == 2
    assert "need at least 3" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        calib_cli.main([str(tmp_path), "--board", "9by6", "--out", "x.json"])
    with pytest.raises(FileNotFoundError):
        Calibration.read(tmp_path / "none.json")


@pytest.mark.skipif(not REAL.is_dir(), reason="real chessboard photos (../shared/data/real) not present")
def test_real_chessboard_photos_under_one_pixel():
    cal = calibrate(REAL, (9, 6), 0.025)
    assert cal.rms_px < 1.0, f"RMS {cal.rms_px:.3f} px"
    assert len(cal.used) >= 10 and len(cal.skipped) >= 1
    assert all(s["reason"] for s in cal.skipped)


def test_a_camera_known_by_its_field_of_view_sees_its_edges_at_half_that_angle(tmp_path, capsys):
    """``bsn-calibrate --hfov``: a pinhole at the video's frame size whose outermost pixel edges lie
    at half the field of view either side of the axis (pixel edges at 0 and W), centred, square."""
    import math

    from tests.fakes import noise_video
    video = noise_video(tmp_path / "drive.mp4", 3, 320, 176)
    out = tmp_path / "cam.json"
    assert calib_cli.main([str(video), "--hfov", "70", "--out", str(out)]) == 0
    read = Calibration.read(out)
    cam = read.intrinsics
    assert (cam.width, cam.height, read.dist) == (320, 176, ())
    assert math.degrees(math.atan2(cam.width - cam.cx, cam.fx) + math.atan2(cam.cx, cam.fx)) == pytest.approx(70.0)
    assert cam.fx == cam.fy and cam.cy == pytest.approx(88.0) and read.intrinsics_method.startswith("field of view")
    assert "70 degrees across" in capsys.readouterr().out
    # a folder of the camera's frames gives the same camera
    frames = tmp_path / "frames"
    frames.mkdir()
    cv2.imwrite(str(frames / "000000.png"), np.zeros((176, 320, 3), np.uint8))
    assert calib_cli.main([str(frames), "--hfov", "70", "--out", str(tmp_path / "f.json")]) == 0
    assert Calibration.read(tmp_path / "f.json").intrinsics.fx == pytest.approx(cam.fx)
    # refused: the user's file without --force, a field of view no forward camera has, --hfov with --mount
    assert calib_cli.main([str(video), "--hfov", "70", "--out", str(out)]) == 2
    assert calib_cli.main([str(video), "--hfov", "700", "--out", str(tmp_path / "x.json")]) == 2
    assert calib_cli.main([str(video), "--hfov", "70", "--mount", "--out", str(tmp_path / "y.json")]) == 2
    err = capsys.readouterr().err
    assert "exists" in err and "20-150 degrees" in err and "--mount" in err
    assert not (tmp_path / "x.json").exists() and not (tmp_path / "y.json").exists()
    # wide: written, with a word on the distortion it cannot know
    assert calib_cli.main([str(video), "--hfov", "130", "--out", str(tmp_path / "wide.json")]) == 0
    assert "bends straight lines" in capsys.readouterr().err
