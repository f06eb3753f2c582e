"""Outputs beside the bus that fail: the alerts go on, the status says DEGRADED, the summary says which
output failed and from which frame, and whatever ends the run, the last word on the bus is UNAVAILABLE.

Full disks are real ones: writes to ``/dev/full`` fail with ENOSPC, as a full file system's do.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest

from bsn_edge.alerts import SystemState
from bsn_edge.alerts.can_codec import decode
from bsn_edge.cli import run as run_cli
from bsn_edge.cli.common import CHECKOUT
from tests.fakes import BUSY_S

FULL = Path("/dev/full")
needs_dev_full = pytest.mark.skipif(not FULL.exists(), reason="this system has no /dev/full")


def bus_frames(rx) -> list:
    out = []
    while (m := rx.recv(timeout=0.2)) is not None:
        d = decode(m.arbitration_id, m.data)
        if d is not None:
            assert d.crc_ok
            out.append(d)
    return out


def run_on_bus(channel: str, argv: list[str]) -> tuple[int, list]:
    with can.Bus(interface="virtual", channel=channel) as rx:
        code = run_cli.main([*argv, "--can", f"virtual:{channel}"])
        return code, bus_frames(rx)


@needs_dev_full
def test_a_frame_log_on_a_full_disk_degrades_and_the_alerts_go_on(setup, tmp_path, capsys):
    model, clip = setup
    summ = tmp_path / "s.json"
    code, got = run_on_bus("bsn-sink-log", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                            str(clip / "calibration.json"), "--log", str(FULL),
                                            "--summary", str(summ)])
    assert code == 0
    status = [d.signals for d in got if d.name == "BSN_Status"]
    hazards = [d for d in got if d.name == "BSN_Hazard"]
    assert status[-1]["System_State"] == SystemState.UNAVAILABLE
    assert all(s["System_State"] == SystemState.DEGRADED and s["Sink_Errors"] == 1 for s in status[1:-1])
    assert len(hazards) == len(status), "a hazard frame every cycle, the log's failure notwithstanding"
    failure = json.loads(summ.read_text())["sinks"]["log"]["failure"]
    assert failure["frame"] == 0 and "No space left" in failure["error"]
    assert "the log output failed at frame 0" in capsys.readouterr().err


@needs_dev_full
def test_a_can_log_on_a_full_disk_degrades_and_the_bus_goes_on(setup, tmp_path, capsys):
    model, clip = setup
    log = tmp_path / "alerts.log"
    log.symlink_to(FULL)
    code, got = run_on_bus("bsn-sink-canlog", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                               str(clip / "calibration.json"), "--can-log", str(log)])
    assert code == 0
    status = [d.signals for d in got if d.name == "BSN_Status"]
    assert status[-1]["System_State"] == SystemState.UNAVAILABLE and status[-1]["Sink_Errors"] == 1
    assert status[0]["Tx_Errors"] == 0, "a log that fails is not a bus that fails"
    assert "the CAN log failed" in capsys.readouterr().err


def test_maps_that_cannot_be_written_degrade_from_the_frame_they_fail(setup, tmp_path, monkeypatch):
    import bsn_edge.runtime.maps as maps_mod
    model, clip = setup
    real, calls = maps_mod.atomic_write_bytes, []

    def write(path, data, durable=False):
        calls.append(path)
        if len(calls) > 6:                     # three frames' maps, then the disk is full
            raise OSError(28, "No space left on device")
        return real(path, data, durable)

    monkeypatch.setattr(maps_mod, "atomic_write_bytes", write)
    summ = tmp_path / "s.json"
    code, got = run_on_bus("bsn-sink-maps", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                             str(clip / "calibration.json"), "--save-maps", str(tmp_path / "maps"),
                                             "--summary", str(summ)])
    assert code == 0
    sinks = json.loads(summ.read_text())["sinks"]
    assert sinks["maps"]["written"] == 3 and sinks["maps"]["failure"]["frame"] == 3
    assert len(list((tmp_path / "maps").glob("*_depth.png"))) == 3
    status = [d.signals for d in got if d.name == "BSN_Status"]
    assert SystemState.DEGRADED in [s["System_State"] for s in status] and status[-1]["Sink_Errors"] == 1


def test_an_overlay_that_cannot_be_finished_is_reported(setup, tmp_path, capsys, monkeypatch):
    """The disk fills as the video is finished: OpenCV's writer says nothing, the read-back does."""
    import cv2

    import bsn_edge.runtime.overlay as overlay_mod
    model, clip = setup
    real = cv2.VideoWriter

    class FillingWriter:
        fourcc = staticmethod(real.fourcc)

        def __init__(self, path, *a):
            self.path, self.w = path, real(path, *a)

        def __getattr__(self, name):
            return getattr(self.w, name)

        def release(self):
            self.w.release()
            with open(self.path, "r+b") as f:     # what a full disk leaves: the header, no index
                f.truncate(64)

    monkeypatch.setattr(overlay_mod.cv2, "VideoWriter", FillingWriter)
    summ = tmp_path / "s.json"
    code, got = run_on_bus("bsn-sink-ov", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                           str(clip / "calibration.json"), "--overlay", str(tmp_path / "ov.mp4"),
                                           "--summary", str(summ)])
    assert code == 0
    sink = json.loads(summ.read_text())["sinks"]["overlay"]
    assert sink["written"] == 15 and "cannot be played back" in sink["failure"]["error"]
    assert "the overlay output failed" in capsys.readouterr().err
    assert got[-1].signals["System_State"] == SystemState.UNAVAILABLE and got[-1].signals["Sink_Errors"] == 1


@needs_dev_full
def test_an_overlay_on_a_full_disk_fails_at_its_first_frame_and_the_alerts_go_on(setup, tmp_path):
    model, clip = setup
    ov = tmp_path / "ov.mp4"
    ov.symlink_to(FULL)
    summ = tmp_path / "s.json"
    code, got = run_on_bus("bsn-sink-ov2", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                            str(clip / "calibration.json"), "--overlay", str(ov), "--summary",
                                            str(summ)])
    assert code == 0
    assert json.loads(summ.read_text())["sinks"]["overlay"]["failure"]["frame"] == 0
    hazards = [d for d in got if d.name == "BSN_Hazard"]
    assert len(hazards) >= 15 and got[-1].signals["Sink_Errors"] == 1


def test_an_output_that_cannot_be_opened_refuses_the_run_with_unavailable(setup, tmp_path, capsys):
    model, clip = setup
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    code, got = run_on_bus("bsn-sink-open", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                             str(clip / "calibration.json"), "--log", str(blocker / "log.jsonl")])
    err = capsys.readouterr().err
    assert code == 2 and "UNAVAILABLE sent" in err and "Traceback" not in err
    assert got and got[-1].signals["System_State"] == SystemState.UNAVAILABLE


def test_a_missing_serial_port_still_tells_the_can_bus(setup, tmp_path, capsys):
    model, clip = setup
    code, got = run_on_bus("bsn-sink-serial", ["--model", str(model), "--source", str(clip / "video.mp4"),
                                               "--serial", str(tmp_path / "no_such_tty")])
    assert code == 2 and "cannot open serial port" in capsys.readouterr().err
    assert [d.signals["System_State"] for d in got if d.name == "BSN_Status"] == [SystemState.UNAVAILABLE]


def test_a_folder_where_no_frame_decodes_is_an_error(setup, tmp_path, capsys):
    model, _ = setup
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(4):
        (folder / f"{i:06d}.png").write_bytes(b"not a picture" * 10)
    code = run_cli.main(["--model", str(model), "--source", str(folder)])
    assert code == 1 and "none of the 4 frames" in capsys.readouterr().err


# HUP and QUIT take the path TERM and INT take (one handler for every stop signal): with the slow tests
@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 0), (signal.SIGINT, 130),
                                           pytest.param(signal.SIGHUP, 129, marks=pytest.mark.slow),
                                           pytest.param(signal.SIGQUIT, 131, marks=pytest.mark.slow)])
def test_a_signal_at_any_moment_of_start_up_ends_with_unavailable_and_no_traceback(setup, tmp_path, sig, code):
    model, clip = setup
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    # signals before main() runs are Python's, not the runtime's: each is sent a given time after the
    # CAN log appears (main() watches signals before it opens any output), however loaded the machine
    for delay in (0.0, 0.4, 1.5):                 # opening the outputs, loading the model, running
        log, summ = tmp_path / f"{sig.name}_{delay}.log", tmp_path / f"{sig.name}_{delay}.json"
        proc = subprocess.Popen([sys.executable, "-m", "bsn_edge.cli.run", "--model", str(model), "--source",
                                 str(clip / "video.mp4"), "--pace", "--can-log", str(log), "--summary", str(summ)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
        deadline = time.monotonic() + 60
        while not log.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        assert log.exists(), f"bsn-run never opened its CAN log (exit {proc.poll()})"
        time.sleep(delay)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        assert "Traceback" not in err, err
        assert proc.returncode == code, err
        msgs = [decode(m.arbitration_id, bytes(m.data)) for m in can.LogReader(str(log))]
        states = [d.signals["System_State"] for d in msgs if d is not None and d.name == "BSN_Status"]
        assert states and states[-1] == SystemState.UNAVAILABLE, (delay, states)
        summary = json.loads(summ.read_text())      # the summary is written, in the first second too
        assert summary["stopped"] and summary["signal"] == sig.name, (delay, summary)


def test_later_signals_change_nothing_the_first_one_started(setup, tmp_path):
    """INT while it runs, then INT, TERM and HUP every 5 ms until the process is gone: the run ends as the
    first asked (exit 130, the summary names SIGINT), UNAVAILABLE last on the bus, the later signals
    absorbed, not fatal, while it stops and while Python shuts down."""
    model, clip = setup
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    log, canlog, summ = tmp_path / "a.jsonl", tmp_path / "a.log", tmp_path / "s.json"
    proc = subprocess.Popen([sys.executable, "-m", "bsn_edge.cli.run", "--model", str(model), "--source",
                             str(clip / "video.mp4"), "--pace", "--log", str(log), "--can-log", str(canlog),
                             "--summary", str(summ)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                            text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not log.exists() or len(log.read_text().splitlines()) < 3):
        time.sleep(0.02)
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    later = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    k = 0
    while proc.poll() is None and time.monotonic() - t0 < 5:   # later signals until it has exited, shutdown included
        try:
            proc.send_signal(later[k % len(later)])
        except ProcessLookupError:
            break
        k += 1
        time.sleep(0.005)
    _, err = proc.communicate(timeout=30)
    ended = time.monotonic() - t0
    assert proc.returncode == 130 and "Traceback" not in err, err
    assert json.loads(summ.read_text())["signal"] == "SIGINT"
    msgs = [decode(m.arbitration_id, bytes(m.data)) for m in can.LogReader(str(canlog))]
    states = [d.signals["System_State"] for d in msgs if d is not None and d.name == "BSN_Status"]
    assert states[-1] == SystemState.UNAVAILABLE
    assert ended < BUSY_S, f"the run took {ended:.2f} s to end"


def test_the_json_lines_of_a_killed_run_are_whole(setup, tmp_path):
    model, clip = setup
    log, canlog = tmp_path / "a.jsonl", tmp_path / "a.log"
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    proc = subprocess.Popen([sys.executable, "-m", "bsn_edge.cli.run", "--model", str(model), "--source",
                             str(clip / "video.mp4"), "--pace", "--log", str(log), "--can-log", str(canlog)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not log.exists() or len(log.read_text().splitlines()) < 5):
        time.sleep(0.02)
    proc.kill()
    proc.wait(timeout=30)
    lines = log.read_text().splitlines()
    assert len(lines) >= 5 and all(json.loads(x)["frame"] == i for i, x in enumerate(lines))
    # every cycle sent before the one in flight is in the CAN log
    msgs = list(can.LogReader(str(canlog)))
    assert len(msgs) >= 2 * (len(lines) - 1), (len(msgs), len(lines))
    assert np.all(np.diff([m.timestamp for m in msgs]) >= 0)


def test_a_sealed_graph_with_the_wrong_output_ranks_is_refused_at_load(setup, tmp_path, capsys):
    """Right names, a valid seal, but [H, W] outputs: refused with a message before any frame."""
    import onnx
    from onnx import TensorProto, helper

    from bsn_edge.export.seal import read_card, set_metadata
    from bsn_edge.modelfile.read import graph_digest
    model, clip = setup
    card = read_card(model)
    h, w = card.input_size
    nodes = [helper.make_node("Cast", ["frame"], ["f"], to=TensorProto.FLOAT),
             helper.make_node("ReduceMean", ["f", "axes"], ["m"], keepdims=0),
             helper.make_node("Sigmoid", ["m"], ["blindspot"]),
             helper.make_node("Add", ["m", "one"], ["depth"])]
    graph = helper.make_graph(nodes, "flat", [helper.make_tensor_value_info("frame", TensorProto.UINT8, [1, h, w, 3])],
                              [helper.make_tensor_value_info("blindspot", TensorProto.FLOAT, [h, w]),
                               helper.make_tensor_value_info("depth", TensorProto.FLOAT, [h, w])],
                              [helper.make_tensor("axes", TensorProto.INT64, [2], [0, 3]),
                               helper.make_tensor("one", TensorProto.FLOAT, [], [1.0])])
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    m.ir_version = 9
    sealed = card.replace(graph_sha256=graph_digest(m.SerializeToString()))
    set_metadata(m, sealed)
    bad = tmp_path / "rank2.onnx"
    onnx.save(m, str(bad))
    code, got = run_on_bus("bsn-sink-rank", ["--model", str(bad), "--source", str(clip / "video.mp4"),
                                            "--allow-unsigned"])
    err = capsys.readouterr().err
    assert code == 2 and "output 'blindspot' is tensor(float) [" in err and "Traceback" not in err
    assert [d.signals["System_State"] for d in got if d.name == "BSN_Status"] == [SystemState.UNAVAILABLE]


def test_frames_after_a_damaged_stretch_keep_their_true_times(tmp_path):
    """A video with its middle zeroed: OpenCV's decoder jumps to the next keyframe; the frames it
    skipped are counted where they were, and every later frame has the time it has in the intact file."""
    import cv2

    from bsn_edge.runtime.sources import VideoFileSource
    intact, broken = tmp_path / "intact.mp4", tmp_path / "broken.mp4"
    w = cv2.VideoWriter(str(intact), cv2.VideoWriter_fourcc(*"mp4v"), 25, (192, 96))
    for i in range(120):
        w.write(np.full((96, 192, 3), 2 * i, np.uint8))     # the frame's number, in its grey level
    w.release()
    data = bytearray(intact.read_bytes())
    a, b = int(len(data) * 0.45), int(len(data) * 0.60)
    data[a:b] = bytes(b - a)
    broken.write_bytes(bytes(data))

    def frames(path):
        src = VideoFileSource(path)
        got = [(c.index, c.t, None if c.frame is None else round(float(c.frame.mean()) / 2)) for c in src]
        src.close()
        return got, src

    clean, _ = frames(intact)
    by_index = {i: (t, n) for i, t, n in clean}
    got, src = frames(broken)
    skipped = [i for i, _, n in got if n is None]
    assert skipped, "the damage was seen"
    after = [(i, t, n) for i, t, n in got if n is not None and i > max(skipped)]
    # the decoder restarts at a keyframe: the frames after it are the intact file's, at the intact file's times
    assert len(after) > 20 and all(by_index[i] == (t, n) for i, t, n in after), after[:5]
    assert [i for i, _, _ in got] == list(range(len(got))), "every index once, skipped ones where they were"
    assert src.failure is None and src.skipped == len(skipped)


@pytest.mark.slow
def test_sigkill_at_twenty_random_moments_loses_nothing_the_bus_carried(setup, tmp_path):
    """The kill test above at 20 random moments (start-up, the first frames, mid-run)."""
    model, clip = setup
    rng = np.random.default_rng(7)
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    for k in range(20):
        log, canlog = tmp_path / f"{k}.jsonl", tmp_path / f"{k}.log"
        proc = subprocess.Popen([sys.executable, "-m", "bsn_edge.cli.run", "--model", str(model), "--source",
                                 str(clip / "video.mp4"), "--pace", "--log", str(log), "--can-log", str(canlog)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        time.sleep(float(rng.uniform(0.2, 3.0)))
        proc.kill()
        proc.wait(timeout=30)
        lines = log.read_text().splitlines() if log.exists() else []
        assert all(json.loads(x)["frame"] == i for i, x in enumerate(lines)), k
        msgs = list(can.LogReader(str(canlog))) if canlog.exists() and canlog.stat().st_size else []
        assert len(msgs) >= 2 * (len(lines) - 1), (k, len(msgs), len(lines))


@pytest.fixture
def read_only_dir(tmp_path):
    """A real read-only file system (a tmpfs mounted ro); needs the right to mount (root)."""
    d = tmp_path / "ro"
    d.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(d)], capture_output=True)
    if r.returncode:
        pytest.skip("mounting a read-only tmpfs needs root (mount(8) refused)")
    yield d
    subprocess.run(["umount", str(d)], check=False)


@pytest.mark.parametrize("flag", ["--log", "--overlay", "--save-maps"])
def test_an_output_on_a_read_only_disk_refuses_the_run_with_unavailable(setup, read_only_dir, flag, capsys):
    model, clip = setup
    target = read_only_dir / {"--log": "a.jsonl", "--overlay": "o.mp4", "--save-maps": "maps"}[flag]
    if flag == "--save-maps":
        target = read_only_dir                  # an existing folder on the read-only disk
    code, got = run_on_bus(f"bsn-ro-{flag[2:]}", ["--model", str(model), "--source", str(clip / "video.mp4"),
                                                   "--calib", str(clip / "calibration.json"), flag, str(target)])
    err = capsys.readouterr().err
    assert code == 2 and "Read-only file system" in err and "Traceback" not in err
    assert [d.signals["System_State"] for d in got if d.name == "BSN_Status"] == [SystemState.UNAVAILABLE]
    assert not any(read_only_dir.iterdir())


def test_a_video_file_source_lets_its_file_go_when_closed(setup):
    from bsn_edge.runtime.sources import VideoFileSource
    _, clip = setup

    def open_fds():
        return len(os.listdir("/proc/self/fd"))

    before = open_fds()
    for _ in range(10):
        src = VideoFileSource(clip / "video.mp4")
        next(iter(src))
        src.close()
    assert open_fds() <= before


def test_a_video_file_is_decoded_on_the_reading_thread_with_the_same_frames(tmp_path):
    """One decoding thread by default (the feeder's priority then holds for decoding too): the frames,
    indices and times are those FFmpeg's own frame threads give; a negative count is refused."""
    import cv2

    from bsn_edge.runtime.sources import VideoFileSource
    from tests.fakes import noise_video
    path = noise_video(tmp_path / "v.mp4", 30, 192, 96, seed=3)

    def frames(**kw):
        src = VideoFileSource(path, **kw)
        threads = src.cap.get(cv2.CAP_PROP_N_THREADS)
        got = [(c.index, c.t, c.frame) for c in src]
        src.close()
        return got, threads

    one, n_one = frames()
    many, _ = frames(decode_threads=0)
    assert n_one == 1 and len(one) == len(many) == 30
    assert all(a[:2] == b[:2] and np.array_equal(a[2], b[2]) for a, b in zip(one, many, strict=True))
    with pytest.raises(ValueError, match="decode_threads"):
        VideoFileSource(path, decode_threads=-1)


def test_frames_in_flight_without_overlap_are_refused_with_unavailable(setup, capsys):
    model, clip = setup
    code, got = run_on_bus("bsn-inflight", ["--model", str(model), "--source", str(clip / "video.mp4"),
                                            "--in-flight", "2", "--in-turn"])
    assert code == 2 and "overlap" in capsys.readouterr().err
    assert [d.signals["System_State"] for d in got if d.name == "BSN_Status"] == [SystemState.UNAVAILABLE]


def test_two_frames_in_flight_run_on_one_thread_each(setup, tmp_path):
    model, clip = setup
    summ = tmp_path / "s.json"
    code, _ = run_on_bus("bsn-inflight2", ["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                                           str(clip / "calibration.json"), "--in-flight", "2", "--summary", str(summ)])
    s = json.loads(summ.read_text())
    assert code == 0 and s["in_flight"] == 2 and s["frames"] == s["valid_frames"] == 15


def test_an_output_on_its_own_thread_writes_every_frame_of_a_file_in_order():
    from bsn_edge.runtime.sinks import GuardedSink
    got = []
    sink = GuardedSink("slow", lambda i: (time.sleep(0.002), got.append(i)), behind=2)
    assert all(sink.write(i, i) for i in range(20))
    sink.close()
    assert got == list(range(20)) and sink.written == 20 and sink.dropped == 0


def test_an_output_behind_a_camera_drops_frames_and_never_holds_the_loop():
    import threading

    from bsn_edge.runtime.sinks import GuardedSink
    gate, got = threading.Event(), []
    sink = GuardedSink("stuck", lambda i: (gate.wait(5), got.append(i)), behind=2, drop_when_full=True)
    t0 = time.monotonic()
    taken = [sink.write(i, i) for i in range(10)]
    assert time.monotonic() - t0 < 1.0, "the loop waited for its output"
    gate.set()
    sink.close()
    # one frame on the sink's thread, two queued, the rest dropped and counted, none of it a fault
    assert sum(taken) == len(got) == sink.written and sink.dropped == 10 - sink.written
    assert 2 <= sink.written <= 3 and sink.ok


def test_an_output_failing_on_its_own_thread_is_a_fault_once_at_the_frame_it_failed():
    from bsn_edge.runtime.sinks import GuardedSink
    faults = []

    def write(i):
        if i >= 3:
            raise OSError(28, "No space left on device")

    sink = GuardedSink("disk", write, on_fault=faults.append, behind=2)
    for i in range(8):
        sink.write(i, i)
    sink.close()
    assert sink.written == 3 and len(faults) == 1 and faults[0].frame == 3 and not sink.ok
    assert not sink.write(9, 9)


def test_an_output_stuck_in_a_write_does_not_hold_up_the_end_of_the_run(monkeypatch):
    import threading

    from bsn_edge.runtime.sinks import GuardedSink
    monkeypatch.setattr(GuardedSink, "STUCK_AFTER_S", 0.2)
    hung, faults, closed = threading.Event(), [], []
    sink = GuardedSink("hung", lambda i: hung.wait(30), close=lambda: closed.append(True), on_fault=faults.append,
                       behind=1)
    sink.write(0, 0)            # taken by the sink's thread, which hangs in it
    time.sleep(0.05)
    sink.write(1, 1)            # queued: the queue is now full
    t0 = time.monotonic()
    sink.close(frame=3)
    assert time.monotonic() - t0 < 2.0
    assert not sink.ok and "given up" in sink.failure.error and len(faults) == 1 and not closed
    hung.set()


def test_an_output_stuck_in_a_write_from_a_file_is_a_fault_and_the_loop_goes_on(monkeypatch):
    import threading

    from bsn_edge.runtime.sinks import GuardedSink
    monkeypatch.setattr(GuardedSink, "STUCK_AFTER_S", 0.2)
    hung, faults = threading.Event(), []
    sink = GuardedSink("hung", lambda i: hung.wait(30), on_fault=faults.append, behind=1)
    began = time.monotonic()
    assert sink.write(0, 0)     # taken by the sink's thread, which hangs in it
    time.sleep(0.05)
    assert sink.write(1, 1)     # queued: the queue is now full
    assert not sink.write(2, 2)     # a file's frame waits for room, but no longer than the sink may hang in one write
    assert 0.2 <= time.monotonic() - began < 2.0
    assert not sink.ok and sink.failure.frame == 0 and "stuck in one write" in sink.failure.error
    assert len(faults) == 1
    t0 = time.monotonic()
    assert not sink.write(3, 3)     # after the fault, no more waiting
    assert time.monotonic() - t0 < 0.15
    sink.close()                    # nor at the end
    assert time.monotonic() - t0 < 0.15 and len(faults) == 1
    hung.set()


def test_the_frame_log_never_ends_in_half_a_line(tmp_path, monkeypatch):
    """A write the disk takes only part of (ENOSPC half-way through a record) is cut back: the file
    holds the whole records before it and nothing of the failed one, and every line parses."""
    import errno
    import os

    from bsn_edge.runtime.sinks import LineLog
    path = tmp_path / "frames.jsonl"
    log = LineLog(path)
    log.open()
    for i in range(3):
        log.write({"frame": i, "levels": ["NONE"] * 3})
    real = os.write

    def half_then_full(fd, data):
        if len(data) > 10:
            real(fd, data[: len(data) // 2])
            return len(data) // 2
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(os, "write", half_then_full)
    with pytest.raises(OSError, match="No space"):
        log.write({"frame": 3, "levels": ["WARNING"] * 3})
    monkeypatch.setattr(os, "write", real)
    log.close()
    log.close()
    text = path.read_text()
    assert text.endswith("\n") and [json.loads(line)["frame"] for line in text.splitlines()] == [0, 1, 2]


@pytest.fixture
def small_disk(tmp_path):
    """A 12 MB file system of its own (tmpfs; skips where this user may not mount one)."""
    where = tmp_path / "disk"
    where.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=12m", "tmpfs", str(where)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small file system here (needs root)")
    yield where
    subprocess.run(["umount", "-l", str(where)], check=False)


def test_an_overlay_filling_its_disk_degrades_at_the_frame_it_fails_not_at_the_end(setup, tmp_path, small_disk):
    from tests.fakes import noise_video
    model, _ = setup
    video = noise_video(tmp_path / "noise.mp4", 120, 1280, 720)
    summ = tmp_path / "s.json"
    # noise fills the disk fastest; a camera sending noise is a fault of its own, so its check is off here
    code, got = run_on_bus("bsn-sink-disk", ["--model", str(model), "--source", str(video), "--overlay",
                                             str(small_disk / "overlay.mp4"), "--summary", str(summ),
                                             "--set", "visibility.enabled=false"])
    s = json.loads(summ.read_text())
    failure = s["sinks"]["overlay"]["failure"]
    assert code == 0 and failure is not None and 0 < failure["frame"] < 110, failure
    status = [d.signals for d in got if d.name == "BSN_Status"]
    # the status turned DEGRADED while the run went on, well before its end, and stayed so
    first = next(i for i, st in enumerate(status) if st["Sink_Errors"] == 1)
    assert first < len(status) - 10 and status[first]["System_State"] == SystemState.DEGRADED
    # and never OK again (a stall's UNAVAILABLE may come between on a busy machine)
    later = [st["System_State"] for st in status[first:-1]]
    assert set(later) <= {SystemState.DEGRADED, SystemState.UNAVAILABLE}, later
    assert status[-1]["System_State"] == SystemState.UNAVAILABLE and s["valid_frames"] == 120
