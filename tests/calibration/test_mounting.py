"""The mounting step against synthetic drives whose camera is known exactly (the clip's rig)."""

import cv2
import numpy as np
import pytest

from bsn_edge.calibration import Calibration
from bsn_edge.calibration.lane_height import LaneHeight
from bsn_edge.calibration.mount_fit import MountFit, MountFitConfig, shrink
from bsn_edge.calibration.mounting_step import MountingRefusedError, calibrate_mounting
from bsn_edge.cli import calibrate as calib_cli
from bsn_edge.synth import SynthConfig, write_clip

LANE_M = 3.2   # the synthetic world's lanes


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """A 60-frame drive with a drawn camera (rig seed 3: 80-degree lens with barrel distortion,
    pitched, yawed and rolled about a degree)."""
    out = tmp_path_factory.mktemp("drive") / "clip"
    write_clip(SynthConfig(frames=60, seed=3, parked=0.3, traffic=0.3), out, video=True, workers=2)
    return out


def frames(clip):
    return [cv2.imread(str(p)) for p in sorted((clip / "rgb").glob("*.png"))]


# the online estimator's pitch and yaw against the truth are in the default run through bsn-run
# (test_bsn_run_leaves_calibrating_and_saves_the_camera_file); its twin here with -m slow
@pytest.mark.parametrize("online", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["tracking", "online"])
def test_pitch_and_yaw_from_the_focus_of_expansion(drive, online):
    """The tracking estimator (bsn-calibrate --mount) and the runtime's lighter online one alike."""
    from bsn_edge.runtime.calibrator import ONLINE_FIT

    truth = Calibration.read(drive / "calibration.json")
    fit = MountFit(truth.intrinsics, truth.dist, ONLINE_FIT if online else MountFitConfig())
    for f in frames(drive):
        fit.add(f)
    m, report = fit.estimate(truth.mounting.height_m)
    assert report["used"] >= 40
    assert m.pitch_deg == pytest.approx(truth.mounting.pitch_deg, abs=0.4)
    assert m.yaw_deg == pytest.approx(truth.mounting.yaw_deg, abs=0.6)
    assert set(report["spread_deg"]) == {"pitch", "yaw", "roll"}


@pytest.mark.parametrize("roll", [-3.0, pytest.param(4.0, marks=pytest.mark.slow)])   # the other sign with -m slow
def test_roll_from_the_road_plane(tmp_path, roll):
    """A camera rolled a few degrees: the road plane's homographies give it back within 1.5 degrees,
    well under the roll itself (0, the value assumed without the road, fails), with its spread."""
    out = tmp_path / "rolled"
    write_clip(SynthConfig(frames=60, seed=3, parked=0.3, traffic=0.3, camera="fixed", roll_deg=roll), out,
               video=False, workers=2)
    truth = Calibration.read(out / "calibration.json")
    assert truth.mounting.roll_deg == roll
    fit = MountFit(truth.intrinsics, truth.dist)
    for f in frames(out):
        fit.add(f)
    m, report = fit.estimate(truth.mounting.height_m)
    assert report["road_plane_pairs"] >= 10 and report["spread_deg"]["roll"] is not None
    assert abs(m.roll_deg - roll) < 1.5, (m.roll_deg, report["spread_deg"])


def test_height_from_the_lane_width(drive):
    truth = Calibration.read(drive / "calibration.json")
    lanes = LaneHeight(truth.intrinsics, truth.dist, truth.mounting)
    for f in frames(drive):
        lanes.add(f)
    h, report = lanes.estimate(LANE_M)
    assert report["frames_used"] >= 30
    assert h == pytest.approx(truth.mounting.height_m, rel=0.1)


def test_standing_still_and_short_clips_are_refused_with_reasons(tmp_path, drive):
    truth = Calibration.read(drive / "calibration.json")
    still = tmp_path / "still.mp4"
    f = frames(drive)[0]
    w = cv2.VideoWriter(str(still), cv2.VideoWriter_fourcc(*"mp4v"), 10, (f.shape[1], f.shape[0]))
    for _ in range(40):
        w.write(f)
    w.release()
    with pytest.raises(MountingRefusedError, match="standing still"):
        calibrate_mounting(still, truth, height_m=1.4)
    with pytest.raises(MountingRefusedError, match="too short"):
        calibrate_mounting(drive / "video.mp4", truth, height_m=1.4, max_frames=12)
    with pytest.raises(ValueError, match="one of them"):
        calibrate_mounting(drive / "video.mp4", truth)


def test_cli_writes_the_camera_file_run_and_label_read(tmp_path, drive, capsys):
    truth = Calibration.read(drive / "calibration.json")
    intr = tmp_path / "intr.json"
    Calibration.of(truth.intrinsics, truth.dist).write(intr)
    out = tmp_path / "cam.json"
    argv = [str(drive / "video.mp4"), "--mount", "--calib", str(intr), "--height", "1.4", "--out", str(out),
            "--max-error", "0.3"]
    assert calib_cli.main(argv) == 0
    cam = Calibration.read(out)
    assert cam.mounting.height_m == 1.4 and cam.dist == truth.dist
    assert cam.mounting_report["used"] > 0 and "spread_deg" in cam.mounting_report
    assert "pitch" in capsys.readouterr().out
    # the user's work is not overwritten without --force
    assert calib_cli.main(argv) == 2
    assert "exists" in capsys.readouterr().err
    assert calib_cli.main([*argv, "--force"]) == 0
    # the height from the lanes instead, through the same command: the clip's true height
    lanes = [str(drive / "video.mp4"), "--mount", "--calib", str(intr), "--lane-width", str(LANE_M), "--out",
             str(tmp_path / "lanes.json"), "--max-error", "0.3"]
    assert calib_cli.main(lanes) == 0
    got = Calibration.read(tmp_path / "lanes.json").mounting
    # the lane-width height over this rig's drives (seeds 3-6) was 1 to 11 % high: the bound is its spread
    assert got.height_m == pytest.approx(truth.mounting.height_m, rel=0.15)
    assert Calibration.read(tmp_path / "lanes.json").mounting_report["height"]["method"].startswith("lane width")


def test_online_estimate_converges_on_a_steady_drive(drive):
    truth = Calibration.read(drive / "calibration.json")
    fit = MountFit(truth.intrinsics, truth.dist, MountFitConfig(max_spread_deg=0.3))
    converged_at, at = None, None
    for i, f in enumerate(frames(drive)):
        fit.add(f)
        m, report = fit.estimate(1.5)
        if report["converged"] and converged_at is None:
            converged_at, at = i, m
    # converged well inside the 60-frame clip, and where it converged it is the clip's true mounting
    assert converged_at is not None and converged_at <= 45, converged_at
    assert abs(at.pitch_deg - truth.mounting.pitch_deg) < 0.3 and abs(at.yaw_deg - truth.mounting.yaw_deg) < 0.3


@pytest.fixture(scope="module")
def long_drive(tmp_path_factory):
    """A 150-frame drive (15 s at 10 frames/s) with the rig of ``drive``."""
    out = tmp_path_factory.mktemp("long_drive") / "clip"
    write_clip(SynthConfig(frames=150, seed=3, parked=0.3, traffic=0.3), out, video=False, workers=2)
    return out


@pytest.mark.slow     # the thread's estimate against the truth is in the default run, through bsn-run (below)
def test_online_calibration_on_its_thread_is_the_estimate_of_the_same_frames_inline(long_drive):
    """The runtime's calibrator runs off the frame path; fed the same frames it reaches the same
    estimate as the estimator run inline, and that estimate is the clip's true mounting."""
    from bsn_edge.runtime.camera_state import CameraState
    from tests.cards import card_for
    truth = Calibration.read(long_drive / "calibration.json")
    intr_only = Calibration.of(truth.intrinsics, truth.dist, None)
    got = {}
    for background in (True, False):
        state = CameraState(card_for((128, 256)), intr_only, height_m=truth.mounting.height_m, background=background)
        state.use_frame_rate(10.0)
        converged_at = None
        for i, f in enumerate(frames(long_drive)):
            state.observe(f)
            if not state.calibrating and converged_at is None:
                converged_at = i
        state.close()
        assert converged_at is not None, state.progress()
        got[background] = (converged_at, state.mounting)
    assert got[True] == got[False], "the same frames, the same estimate, taken up at the same frame"
    m = got[True][1]
    assert abs(m.pitch_deg - truth.mounting.pitch_deg) < 0.3 and abs(m.yaw_deg - truth.mounting.yaw_deg) < 0.3


def test_bsn_run_leaves_calibrating_and_saves_the_camera_file(long_drive, small_light_onnx, tmp_path, capsys):
    """Online calibration through the product: CALIBRATING on the bus until the estimate converges,
    then not; --save-calib writes the camera file with the estimate, near the clip's true mounting."""
    import can

    from bsn_edge.alerts import SystemState
    from bsn_edge.alerts.can_codec import decode
    from bsn_edge.cli import run as run_cli
    truth = Calibration.read(long_drive / "calibration.json")
    Calibration.of(truth.intrinsics, truth.dist, None).write(tmp_path / "intrinsics.json")
    model = small_light_onnx((128, 256))
    saved = tmp_path / "cam.json"
    with can.Bus(interface="virtual", channel="bsn-calib-run") as rx:
        assert run_cli.main(["--model", str(model), "--source", str(long_drive / "rgb"), "--calib",
                             str(tmp_path / "intrinsics.json"), "--height", f"{truth.mounting.height_m}",
                             "--save-calib", str(saved), "--can", "virtual:bsn-calib-run"]) == 0
        states = []
        while (m := rx.recv(timeout=0.2)) is not None:
            d = decode(m.arbitration_id, m.data)
            if d is not None and d.name == "BSN_Status":
                states.append(d.signals["System_State"])
    # DEGRADED (too slow) and UNAVAILABLE (a stall: the loop held up past the deadline) outrank CALIBRATING
    # and come and go with the machine's load: what must hold is CALIBRATING from the start, then, once the
    # estimate has converged, never again
    busy = {SystemState.DEGRADED, SystemState.UNAVAILABLE}
    assert next(s for s in states if s not in busy) == SystemState.CALIBRATING, states
    after = states[len(states) - states[::-1].index(SystemState.CALIBRATING):]
    assert set(states[:-len(after)]) <= {SystemState.CALIBRATING} | busy, states
    assert len(after) > 10, after
    got = Calibration.read(saved).mounting
    assert abs(got.pitch_deg - truth.mounting.pitch_deg) < 0.3 and abs(got.yaw_deg - truth.mounting.yaw_deg) < 0.3
    import json
    import re
    written = json.loads(saved.read_text())
    assert not {"board", "square_m", "rms_px", "used", "skipped"} & set(written), "no chessboard was used"
    # the end lines say when calibration converged: the frame, and its time at the folder's 10 frames/s
    printed = capsys.readouterr()
    said = re.search(r"online, converged at frame (\d+), ([\d.]+) s in", printed.out)
    assert said and 0 < int(said[1]) <= len(list((long_drive / "rgb").iterdir()))
    assert float(said[2]) == pytest.approx(int(said[1]) / 10.0)
    # and the progress line's last word on the camera is the converged one, not a frozen "calibrating"
    last = printed.err.replace("\r", "\n").strip().splitlines()[-1]
    assert f"calibrated: pitch {got.pitch_deg:+.2f} yaw {got.yaw_deg:+.2f} deg, converged at frame {said[1]}" in last


def test_a_camera_file_that_cannot_be_saved_when_calibration_converges_degrades_the_drive_not_ends_it(
        long_drive, small_light_onnx, tmp_path, capsys, monkeypatch):
    """--save-calib on a disk that fills up before calibration converges: once stopped the whole drive
    (exit 2, "could not start", no summary); now the drive runs to its end, the failure named with its file
    and frame in the summary's outputs, DEGRADED on the bus from then on."""
    import json

    import can

    from bsn_edge.alerts import SystemState
    from bsn_edge.alerts.can_codec import decode
    from bsn_edge.calibration import camera_file
    from bsn_edge.cli import run as run_cli
    from tests.fakes import full_disk_for

    truth = Calibration.read(long_drive / "calibration.json")
    Calibration.of(truth.intrinsics, truth.dist, None).write(tmp_path / "intrinsics.json")
    saved, summary = tmp_path / "cam.json", tmp_path / "s.json"
    full_disk_for(saved, monkeypatch, camera_file)
    frames = len(list((long_drive / "rgb").iterdir()))
    with can.Bus(interface="virtual", channel="bsn-calib-full") as rx:
        code = run_cli.main(["--model", str(small_light_onnx((128, 256))), "--source", str(long_drive / "rgb"),
                             "--calib", str(tmp_path / "intrinsics.json"), "--height", f"{truth.mounting.height_m}",
                             "--save-calib", str(saved), "--summary", str(summary), "--can", "virtual:bsn-calib-full"])
        states = []
        while (m := rx.recv(timeout=0.2)) is not None:
            d = decode(m.arbitration_id, m.data)
            if d is not None and d.name == "BSN_Status":
                states.append(d.signals["System_State"])
    s = json.loads(summary.read_text())
    err = capsys.readouterr().err
    assert code == 0 and s["frames"] == frames, (code, s["frames"], err[-400:])
    failure = s["sinks"]["camera file"]["failure"]
    assert str(saved) in failure["error"] and "No space left" in failure["error"] and failure["frame"] > 0, failure
    assert s["faults"]["sink_errors"] == 1 and not saved.exists()
    assert "camera file output failed at frame" in err, err[-400:]
    # converged, then never OK again: DEGRADED (a failed output), or UNAVAILABLE at a stall or the end
    after = states[len(states) - states[::-1].index(SystemState.CALIBRATING):]
    assert after and SystemState.DEGRADED in after and SystemState.OK not in after, after


def test_road_normal_of_exact_correspondences_is_the_plane_down_direction():
    """Road corners seen from a known camera before and after a known motion (analytic, no picture):
    the plane solve gives the road's down direction in the camera frame; a car ahead moving with the
    ego (corners that hardly move) does not pull it."""
    import numpy as np

    from bsn_edge.calibration.mount_fit import _road_normal
    from bsn_edge.mounting import Mounting

    cam_from_level = Mounting(1.4, 3.0, -1.5, 2.0).rotation()
    down = cam_from_level @ np.array([0.0, 1.0, 0.0])          # level y points down
    rng = np.random.default_rng(0)
    ground = np.c_[rng.uniform(-4, 4, 300), np.full(300, 1.4), rng.uniform(6, 30, 300)]   # level frame
    turn = Mounting(1.0, 0.0, 0.3, 0.0).rotation()               # the car yaws 0.3 degrees
    step = np.array([0.0, 0.0, 1.2])                             # and moves 1.2 m forward
    x0 = ground @ cam_from_level.T
    x1 = ((ground - step) @ turn.T) @ cam_from_level.T           # the same points, next camera
    R = cam_from_level @ turn @ cam_from_level.T                 # X1 = R X0 + t
    t = -cam_from_level @ turn @ step
    car = np.c_[rng.uniform(-0.8, 0.8, 60), rng.uniform(0.6, 1.3, 60), np.full(60, 12.0)] @ cam_from_level.T
    n0 = np.r_[x0[:, :2] / x0[:, 2:], car[:, :2] / car[:, 2:]]
    n1 = np.r_[x1[:, :2] / x1[:, 2:], car[:, :2] / car[:, 2:]]
    forward = -R.T @ t / np.linalg.norm(t)
    nd = _road_normal(n0, n1, R, t / np.linalg.norm(t), forward)
    assert nd is not None
    assert np.degrees(np.arccos(np.clip(nd @ down, -1, 1))) < 0.05


@pytest.mark.parametrize("raw, size", [((1280, 720), (480, 270)), ((1920, 1080), (480, 270)), ((960, 540), (480, 270)),
                                       ((512, 256), (480, 240))])
def test_frames_are_shrunk_to_the_working_width_without_moving_anything(raw, size):
    """Each pixel of the shrunk frame holds what the whole frame scaled to its size has there: a ramp
    of each pixel's own column (and row) reads (x + 0.5) * W / w - 0.5, the pixel-centre mapping the
    scaled intrinsics assume."""
    (W, H), (w, h) = raw, size
    cols = np.tile(np.arange(W, dtype=np.float32), (H, 1))
    rows = np.tile(np.arange(H, dtype=np.float32)[:, None], (1, W))
    got_c, got_r = shrink(cols, size), shrink(rows, size)
    assert got_c.shape == got_r.shape == (h, w)
    want_c = (np.arange(w) + 0.5) * W / w - 0.5
    want_r = (np.arange(h) + 0.5) * H / h - 0.5
    assert np.abs(got_c - want_c[None, :])[:, 1:-1].max() < 1e-3
    assert np.abs(got_r - want_r[:, None])[1:-1].max() < 1e-3
