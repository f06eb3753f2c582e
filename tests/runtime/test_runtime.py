"""The edge loop end to end on tiny data, with every fault injected and survived."""

import json
import threading
import time

import can
import cv2
import numpy as np
import onnx
import pytest
import serial

from bsn_edge.alerts import SystemState
from bsn_edge.alerts.can_codec import decode
from bsn_edge.alerts.can_output import CanSender
from bsn_edge.alerts.serial_output import SerialSender
from bsn_edge.cli import listen as listen_cli
from bsn_edge.cli import run as run_cli
from bsn_edge.cli.common import REAL_DATA
from bsn_edge.runtime import Engine, RuntimeConfig, open_source, run
from bsn_edge.runtime.sources import ImageFolderSource
from tests.fakes import FullBus, GonePort, mounted


def test_video_to_can_log_that_both_decoders_read(setup, tmp_path, capsys):
    model, clip = setup
    log, asc = tmp_path / "frames.jsonl", tmp_path / "alerts.log"
    # the clip's own camera file (it carries the mounting): no online calibration, OK from the start
    assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--can-log", str(asc),
                         "--log", str(log), "--overlay", str(tmp_path / "ov.mp4"), "--summary",
                         str(tmp_path / "s.json"), "--calib", str(clip / "calibration.json")]) == 0
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["frames"] == summary["valid_frames"] == 15
    assert summary["fps"] == pytest.approx(15 / summary["seconds"], rel=0.02)
    assert set(summary["stage_share"]) == {"decode", "preprocess", "visibility", "inference", "postprocess", "send",
                                           "outputs"}
    assert summary["p99_ms"] >= summary["p50_ms"] > 0
    lines = [json.loads(x) for x in log.read_text().splitlines()]
    assert len(lines) == 15 and all(len(x["levels"]) == 3 for x in lines)
    cap = cv2.VideoCapture(str(tmp_path / "ov.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 15
    capsys.readouterr()
    assert listen_cli.main(["--can-log", str(asc)]) == 0
    out = capsys.readouterr()
    assert "hazard 0 [alive 0]" in out.out and "status 0 [alive 0]" in out.out and "0 with a bad CRC, 0 lost" in out.err
    # 15 frames at 10 fps = 1.4 s on the video's clock: a cycle every 0.1 s, then the final UNAVAILABLE
    assert summary["cycles_sent"] == 16
    # time in each state is the run's: the last word (UNAVAILABLE, whatever ends a run) is not counted
    states = summary["states_s"]
    assert sum(states.values()) == pytest.approx(1.5) and "UNAVAILABLE" not in states, states
    last = out.out.strip().splitlines()[-1].split(" s  ", 1)[1]       # after the frame's time
    assert last.startswith("status 15 [alive 0]: UNAVAILABLE"), "the counter wraps at 15, the number goes on"
    assert "status 14 [alive 14]: OK" in out.out


def test_corrupt_and_resized_frames_are_counted(setup, tmp_path):
    model, clip = setup
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(8):
        img = cv2.imread(str(clip / "rgb" / f"{i:06d}.png"))
        if i == 5:
            img = cv2.resize(img, (320, 160))
        cv2.imwrite(str(folder / f"{i:06d}.png"), img)
    (folder / "000003.png").write_bytes(b"\x89PNG\r\n\x1a\n this is not an image")
    summary = run(Engine(model), ImageFolderSource(folder), [])
    # the resized frame is not run: warped as the source's camera it would be stretched
    assert summary["frames"] == 8 and summary["valid_frames"] == 6
    assert summary["faults"]["decode_errors"] == 1 and summary["faults"]["size_changes"] == 1


def test_a_cut_jpeg_and_a_frame_of_another_aspect_are_decode_faults_on_the_bus(setup, tmp_path):
    """Ten JPEG frames: the 4th cut short with garbage after it (it decodes, libjpeg only warns), the 7th
    4:3 among 2:1 ones. Neither is run; both reach the bus's Decode_Errors (decoded with cantools) and
    the frame log names each."""
    import cantools

    from bsn_edge.alerts.can_codec import DBC_PATH
    model, clip = setup
    folder = tmp_path / "jpegs"
    folder.mkdir()
    for i in range(10):
        img = cv2.imread(str(clip / "rgb" / f"{i:06d}.png"))
        if i == 6:
            img = cv2.resize(img, (192, 144))
        _, jpg = cv2.imencode(".jpg", img)
        data = jpg.tobytes()
        if i == 3:
            data = data[: len(data) // 2] + bytes(np.random.default_rng(0).integers(0, 255, 300, dtype=np.uint8))
        (folder / f"{i:06d}.jpg").write_bytes(data)
    assert cv2.imread(str(folder / "000003.jpg")) is not None, "OpenCV decodes the cut file: it must be caught"
    db = cantools.database.load_file(str(DBC_PATH))
    log = tmp_path / "frames.jsonl"
    with can.Bus(interface="virtual", channel="bsn-rt-cut") as rx, CanSender("virtual", "bsn-rt-cut") as tx:
        summary = run(Engine(model), ImageFolderSource(folder), [tx], log=log)
        st = [db.decode_message(m.arbitration_id, bytes(m.data)) for m in iter(lambda: rx.recv(0.2), None)
              if m.arbitration_id == 0x501]
    assert summary["frames"] == 10 and summary["valid_frames"] == 8
    assert summary["faults"]["decode_errors"] == 1 and summary["faults"]["size_changes"] == 1
    assert st[-1]["Decode_Errors"] == 2
    faults = {json.loads(x)["frame"]: json.loads(x).get("fault") for x in log.read_text().splitlines()}
    assert faults[3] == "decode_errors" and faults[6] == "size_changes"
    assert all(f is None for k, f in faults.items() if k not in (3, 6))


class NanEngine(Engine):
    """Returns NaN from the 4th frame on: a model gone wrong."""

    calls = 0

    def infer(self, batch):
        prob, depth = super().infer(batch)
        NanEngine.calls += 1
        if NanEngine.calls > 1 + 3 + 3:  # after the self-test, the 3 warm-up runs and 3 frames
            prob = np.full_like(prob, np.nan)
        return prob, depth


def test_nan_outputs_make_the_system_unavailable_on_the_bus(setup):
    model, clip = setup
    with can.Bus(interface="virtual", channel="bsn-rt-nan") as rx, CanSender("virtual", "bsn-rt-nan") as tx:
        summary = run(NanEngine(model), open_source(str(clip / "video.mp4")), [tx],
                      RuntimeConfig(cycle_s=0.1))
        msgs = []
        while (m := rx.recv(timeout=0.2)) is not None:
            msgs.append(decode(m.arbitration_id, m.data))
    assert summary["faults"]["nan_outputs"] == 12
    states = [d.signals["System_State"] for d in msgs if d.name == "BSN_Status"]
    # the last cycle is UNAVAILABLE whatever happens: the NaN frames must have made it so before the end
    assert SystemState.UNAVAILABLE not in states[:3] and SystemState.UNAVAILABLE in states[3:-1]
    assert [d.signals["Invalid_Outputs"] for d in msgs if d.name == "BSN_Status"][-1] > 0


def test_failing_senders_never_stop_the_loop(setup):
    model, clip = setup

    tx = CanSender("virtual", "x", bus=FullBus())
    sx = SerialSender("socket://127.0.0.1:9", port=GonePort(), retry_s=0.0)  # nothing listens: reopen fails
    summary = run(Engine(model), open_source(str(clip / "video.mp4")), [tx, sx])
    assert summary["frames"] == 15
    # 15 cycles on the video's clock and the final UNAVAILABLE: every one counted as failed
    assert summary["faults"]["tx_errors"] == 16 and summary["faults"]["tx_full"] == 16
    assert summary["faults"]["serial_errors"] == 16
    assert summary["senders"]["serial"]["errors"] == 16


def test_serial_output_decodes_on_loop(setup, tmp_path):
    model, clip = setup
    port = serial.serial_for_url("loop://", timeout=0.1)
    sx = SerialSender("loop://", port=port)
    run(Engine(model), open_source(str(clip / "video.mp4")), [sx], max_frames=5)
    from bsn_edge.alerts.serial_codec import FrameDecoder
    got = list(FrameDecoder().feed(port.read(10000)))
    assert len(got) == 12 and all(decode(f, d).crc_ok for f, d in got)   # 5 cycles and the final one


def test_bad_inputs_are_explained(setup, tmp_path, capsys):
    model, clip = setup
    assert run_cli.main(["--model", str(tmp_path / "nope.onnx"), "--source", str(clip)]) == 2
    assert "not found" in capsys.readouterr().err
    assert run_cli.main(["--model", str(model), "--source", str(tmp_path / "missing.mp4")]) == 2
    assert "not a file, a folder" in capsys.readouterr().err
    other = tmp_path / "plain.onnx"
    plain = onnx.load(str(model))
    del plain.metadata_props[:]
    onnx.save(plain, str(other))
    assert run_cli.main(["--model", str(other), "--source", str(clip)]) == 2
    assert "not a bsn-export model" in capsys.readouterr().err


def decode_log(path) -> list[SystemState]:
    """Every status frame of a CAN log, decoded by the DBC (CRC checked), in order."""
    out = []
    with can.LogReader(str(path)) as reader:
        for m in reader:
            d = decode(m.arbitration_id, m.data)
            if d is not None and d.name == "BSN_Status":
                assert d.crc_ok
                out.append(SystemState(int(d.signals["System_State"])))
    return out


def test_camera_file_with_a_mounting_is_used_from_the_first_frame(setup, tmp_path):
    from bsn_edge.calibration import Calibration
    from bsn_edge.camera import Intrinsics
    from bsn_edge.mounting import Mounting
    model, clip = setup
    cal = Calibration(Intrinsics(300.0, 300.0, 96.0, 48.0, 192, 96), dist=(-0.2, 0.05, 0.0, 0.0, 0.0),
                      mounting=Mounting(1.2, -1.5, 2.0, 0.5))
    cal.write(tmp_path / "c.json")
    log = tmp_path / "a.log"
    assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                         str(tmp_path / "c.json"), "--max-frames", "3", "--summary", str(tmp_path / "s.json"),
                         "--can-log", str(log)]) == 0
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["valid_frames"] == 3 and s["camera"]["calibrating"] is False
    assert s["camera"]["mounting"]["height_m"] == 1.2
    assert SystemState.CALIBRATING not in decode_log(log)


def test_without_a_mounting_the_bus_says_calibrating(setup, tmp_path):
    model, clip = setup
    log = tmp_path / "a.log"
    assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--can-log", str(log),
                         "--summary", str(tmp_path / "s.json")]) == 0
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["camera"]["calibrating"] is True and "assumed" in s["camera"]["intrinsics"]
    states = decode_log(log)
    # while calibrating, never OK; and the last word is UNAVAILABLE as always
    assert set(states) <= {SystemState.CALIBRATING, SystemState.UNAVAILABLE}
    assert SystemState.CALIBRATING in states and states[-1] == SystemState.UNAVAILABLE


def test_saved_maps_and_overlay_are_in_the_raw_frames_pixels(setup, tmp_path):
    from bsn_edge.runtime.maps import read_depth_map
    model, clip = setup
    maps = tmp_path / "maps"
    assert run_cli.main(["--model", str(model), "--source", str(clip / "rgb"), "--max-frames", "2",
                         "--save-maps", str(maps), "--overlay", str(tmp_path / "o.mp4")]) == 0
    first = sorted((clip / "rgb").iterdir())[0].stem
    prob = cv2.imread(str(maps / f"{first}_blindspot.png"), cv2.IMREAD_UNCHANGED)
    depth = read_depth_map(maps / f"{first}_depth.png")
    assert prob.dtype == np.uint8 and prob.shape == (96, 192)
    assert depth.shape == (96, 192) and depth.max() > 0
    cap = cv2.VideoCapture(str(tmp_path / "o.mp4"))
    ok, frame = cap.read()
    assert ok and frame.shape[:2] == (96, 192)
    # the user's files are never silently replaced
    (tmp_path / "cal.json").write_text("{}")
    assert run_cli.main(["--model", str(model), "--source", str(clip / "rgb"), "--save-calib",
                         str(tmp_path / "cal.json")]) == 2
    # a second run into the same maps folder would mix two runs' maps: refused, unless --force
    before = {p.name: p.stat().st_mtime_ns for p in maps.iterdir()}
    again = ["--model", str(model), "--source", str(clip / "rgb"), "--max-frames", "1", "--save-maps", str(maps)]
    assert run_cli.main(again) == 2
    assert {p.name: p.stat().st_mtime_ns for p in maps.iterdir()} == before
    assert run_cli.main([*again, "--force"]) == 0
    assert (maps / f"{first}_depth.png").stat().st_mtime_ns > before[f"{first}_depth.png"]


REAL_CLIP = REAL_DATA / "dashcam_highway.mp4"


@pytest.mark.skipif(not REAL_CLIP.is_file(), reason="the real dashcam clip (../shared/data/real) is not present")
def test_real_dashcam_clip(setup, tmp_path):
    """A real 960x540 clip through the loop: resized once, every frame valid, CAN decodable."""
    model, _ = setup
    argv = ["--model", str(model), "--source", str(REAL_CLIP), "--max-frames", "40", "--can-log",
            str(tmp_path / "a.log"), "--summary", str(tmp_path / "s.json")]
    assert run_cli.main(argv) == 0
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["frames"] == s["valid_frames"] == 40 and s["faults"]["decode_errors"] == 0
    assert listen_cli.main(["--can-log", str(tmp_path / "a.log")]) == 0


class GatedCamera:
    """A camera whose frame ``i`` comes only when the test opens gate ``i``: which frames the reader
    has delivered is decided by the test, not by how the threads are scheduled."""

    def __init__(self, frames: int) -> None:
        self.gates = [threading.Event() for _ in range(frames)]
        self.i = 0

    def isOpened(self):
        return True

    def read(self):
        if self.i >= len(self.gates):
            return False, None
        self.gates[self.i].wait(10)
        self.i += 1
        return True, np.full((8, 8, 3), self.i - 1, np.uint8)

    def release(self):
        pass


def wait_for(cond, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.001)


def test_live_source_keeps_the_newest_frame_and_counts_drops():
    """A reader thread that outruns a slow consumer: stale frames are dropped and counted."""
    from bsn_edge.runtime.live_source import LiveSource, Reconnect
    cam = GatedCamera(6)
    src = LiveSource("camera", Reconnect(max_tries=0), opener=lambda _: cam)
    it = iter(src)
    cam.gates[0].set()
    assert int(next(it).frame[0, 0, 0]) == 0
    for g in cam.gates[1:4]:                 # three frames arrive while the consumer is busy
        g.set()
    wait_for(lambda: src.dropped == 2)       # 1 and 2 were replaced before anyone took them
    assert int(next(it).frame[0, 0, 0]) == 3, "the newest frame, never a stale one"
    cam.gates[4].set()
    assert int(next(it).frame[0, 0, 0]) == 4
    cam.gates[5].set()
    seen = [int(c.frame[0, 0, 0]) for c in it]      # 5, then the camera ends
    src.close()
    assert seen == [5] and src.dropped == 2


def test_frames_replaced_before_the_loop_first_asks_are_not_drops():
    """A camera delivers while the model warms up: those frames were never due, so they are counted
    apart (``before_start``) and the bus's dropped-frames counter starts at 0."""
    from bsn_edge.runtime.live_source import LiveSource, Reconnect
    cam = GatedCamera(5)
    src = LiveSource("camera", Reconnect(max_tries=0), opener=lambda _: cam)
    for g in cam.gates[:3]:                  # 0, 1, 2 arrive before anyone asks
        g.set()
    wait_for(lambda: src.before_start == 2)
    it = iter(src)
    assert int(next(it).frame[0, 0, 0]) == 2 and src.dropped == 0
    for g in cam.gates[3:]:                  # 3 and 4 arrive while the consumer is busy: 3 is dropped
        g.set()
    wait_for(lambda: src.dropped == 1)
    seen = [int(c.frame[0, 0, 0]) for c in it]
    src.close()
    assert seen == [4] and (src.before_start, src.dropped) == (2, 1)


def test_a_narrow_camera_reads_no_blind_spot_in_the_mirrored_border():
    """A 40 degree camera fills tan(20) / tan(40) of an 80 degree model camera's width; outside it
    the model sees the frame mirrored, and nothing found there may reach the sectors."""
    from bsn_edge.alerts.sectors import blind_spots
    from bsn_edge.calibration import Calibration
    from bsn_edge.camera import Intrinsics
    from bsn_edge.mounting import Mounting

    model, mount = Intrinsics.from_fov(512, 256, 80.0), Mounting(1.5, 1.5)
    mf = Calibration.of(Intrinsics.from_fov(640, 360, 40.0), (), mount).model_frame(640, 360, model, mount)
    mask = blind_spots(np.ones((256, 512), np.float32), 0.5, mf)
    cols = np.nonzero(mask.any(axis=0))[0]
    half = model.fx * np.tan(np.radians(20.0))
    assert cols.min() == pytest.approx(256 - half, abs=1.5) and cols.max() == pytest.approx(256 + half, abs=1.5)


class SlowEngine(Engine):
    """An engine whose every inference takes 0.25 s on a fake processing clock."""

    now = 0.0

    def infer(self, batch):
        SlowEngine.now += 0.25
        return super().infer(batch)


def test_the_bus_and_overlay_carry_the_rate_achieved_not_the_files(setup, tmp_path):
    model, clip = setup
    SlowEngine.now = 0.0
    with can.Bus(interface="virtual", channel="bsn-rt-rate") as rx, CanSender("virtual", "bsn-rt-rate") as tx:
        run(SlowEngine(model), open_source(str(clip / "video.mp4")), [tx], RuntimeConfig(cycle_s=0.1),
            camera=mounted(Engine(model), clip), clock=lambda: SlowEngine.now)
        msgs = []
        while (m := rx.recv(timeout=0.2)) is not None:
            msgs.append(decode(m.arbitration_id, m.data))
    status = [d.signals for d in msgs if d.name == "BSN_Status"]
    running = [s for s in status if s["System_State"] != SystemState.UNAVAILABLE]
    assert running, "some cycles were sent while the model ran"
    # the clip is 10 frames/s; this engine manages 4 on its clock: the bus says 4, and DEGRADED (floor 8)
    assert all(3.5 <= s["Frame_Rate"] <= 4.5 for s in running[3:]), [s["Frame_Rate"] for s in running]
    assert all(s["System_State"] == SystemState.DEGRADED for s in running[3:])


def test_the_overlay_tints_the_blind_spots_and_nothing_else():
    """Drawn over a frame of the model camera's own size (the warp then maps pixels to themselves):
    inside the mask each pixel is 0.45 of itself and 0.55 of the tint (to rounding), outside it is
    the frame's, under the bars and the text."""
    from bsn_edge.alerts.frame import AlertFrame, SectorAlert
    from bsn_edge.alerts.sectors import SectorGeometry
    from bsn_edge.alerts.state_machine import Level
    from bsn_edge.model_frame import ModelFrame, model_camera
    from bsn_edge.runtime.overlay import TINT, TINT_WEIGHT, draw
    cam, mount = model_camera((128, 256))
    mf = ModelFrame.resize_only(cam, mount, 256, 128)
    frame = np.random.default_rng(0).integers(0, 256, (128, 256, 3), dtype=np.uint8)
    mask = np.zeros((128, 256), bool)
    mask[60:90, 30:120] = True
    none = SectorAlert(0.0, Level.NONE, None)
    geometry = SectorGeometry(cam, RuntimeConfig().sectors)
    img = draw(frame, mf, mask, AlertFrame(0.0, (none,) * 3, SystemState.OK, 25.0), geometry)
    # the picture between the bars on top and the text below, off the sector edges' lines
    away = np.zeros_like(mask)
    away[24:110] = True
    cols = mf.raw_column_sector(geometry.column_sector)
    for edge in np.flatnonzero(np.diff(cols)):
        away[:, max(0, edge - 1):edge + 3] = False
    want = frame * (1 - TINT_WEIGHT) + np.array(TINT) * TINT_WEIGHT
    assert np.abs(img[mask & away].astype(float) - want[mask & away]).max() <= 1.0
    assert np.array_equal(img[away & ~mask], frame[away & ~mask])


def test_a_picture_of_another_size_in_a_folder_gets_no_model_frame_of_its_own(setup, tmp_path):
    """A 4000x2000 picture among 192x96 frames is counted as a size change before anything is built for
    it: neither online calibration nor a model frame (the warp maps of a 25-megapixel picture took 580 MB)
    sees it. The camera's model frames are read back: only the folder's size was ever built."""
    from bsn_edge.runtime.camera_state import CameraState

    model, clip = setup
    folder = tmp_path / "pics"
    folder.mkdir()
    for i in range(8):
        img = cv2.imread(str(clip / "rgb" / f"{i:06d}.png"))
        cv2.imwrite(str(folder / f"{i:06d}.png"), cv2.resize(img, (4000, 2000)) if i == 5 else img)

    built, observed = [], []

    class Sizes(CameraState):
        def frame_for(self, frame):
            built.append(frame.shape[:2])
            return super().frame_for(frame)

        def observe(self, frame):
            observed.append(frame.shape[:2])
            super().observe(frame)

    engine = Engine(model)
    summary = run(engine, ImageFolderSource(folder), [], camera=Sizes(engine.card))
    assert summary["frames"] == 8 and summary["valid_frames"] == 7 and summary["faults"]["size_changes"] == 1
    assert set(built) == set(observed) == {(96, 192)}


def test_a_sector_label_names_its_sector_when_it_fits_and_drops_the_name_when_not():
    import cv2

    from bsn_edge.runtime.overlay import LABEL_FONT, LABEL_SCALE, _fitted

    texts = ("FAR_LEFT CAUTION 15m", "CAUTION 15m", "CAUTION")
    width = [cv2.getTextSize(t, LABEL_FONT, LABEL_SCALE, 1)[0][0] for t in texts]
    assert width[0] > width[1] > width[2], "each shorter"
    assert [_fitted(texts, w) for w in (1000, width[0], width[0] - 1, width[1] - 1, 3)] == \
        ["FAR_LEFT CAUTION 15m", "FAR_LEFT CAUTION 15m", "CAUTION 15m", "CAUTION", "CAUTION"]
