"""Faults injected into the edge runtime, with what reaches the bus asserted: a damaged model, a
damaged video, a stalled stream, two threads hammering the health, SIGTERM."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import ClassVar

import can
import cantools
import numpy as np
import onnx
import pytest

from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
from bsn_edge.alerts.can_codec import DBC_PATH, decode
from bsn_edge.alerts.can_output import CanSender
from bsn_edge.alerts.health import Health, HealthConfig
from bsn_edge.card import CARD_SHA_KEY, ModelCard, card_digest
from bsn_edge.cli import run as run_cli
from bsn_edge.cli.common import CHECKOUT
from bsn_edge.export.seal import set_metadata
from bsn_edge.runtime import Engine, ModelError, Reconnect, RuntimeConfig, open_source, run
from bsn_edge.runtime.cycle import CycleEmitter, Heartbeat
from bsn_edge.runtime.live_source import LiveSource
from tests.fakes import SHIPPED, long_video, mounted


def status_of(m) -> int | None:
    """The system state a CAN message carries, if it is a status message (its CRC checked)."""
    d = decode(m.arbitration_id, m.data)
    if d is None or d.name != "BSN_Status":
        return None
    assert d.crc_ok
    return int(d.signals["System_State"])


def statuses(rx) -> list[int]:
    out = []
    while (m := rx.recv(timeout=0.2)) is not None:
        if (state := status_of(m)) is not None:
            out.append(state)
    return out


def rewrite_card(src: Path, dst: Path, **changes) -> None:
    """A model whose card was changed and re-digested, as a buggy or hostile export would write it."""
    m = onnx.load(str(src))
    card = ModelCard.from_metadata({p.key: p.value for p in m.metadata_props})
    set_metadata(m, card.replace(**changes))
    onnx.save(m, str(dst))


# -- a damaged model never starts, and says UNAVAILABLE first ----------------------------------------

def scale_offset(path: Path) -> int:
    """Byte offset in the file of a quantization scale's raw data (an initializer named *_scale)."""
    m = onnx.load(str(path))
    data = path.read_bytes()
    for init in m.graph.initializer:
        if init.name.endswith("_scale") and init.raw_data and data.count(init.raw_data) == 1:
            return data.index(init.raw_data)
    raise AssertionError("no quantization scale with unique bytes")


@pytest.mark.skipif(not SHIPPED.is_file(), reason="the shipped model is not in this checkout")
def test_a_flipped_byte_in_a_quantization_scale_refuses_to_start(setup, tmp_path, capsys):
    _, clip = setup
    data = bytearray(SHIPPED.read_bytes())
    at = scale_offset(SHIPPED)
    data[at + 2] ^= 0x01
    bad = tmp_path / "flipped.onnx"
    bad.write_bytes(bytes(data))
    with can.Bus(interface="virtual", channel="bsn-fs-flip") as rx:
        rc = run_cli.main(["--model", str(bad), "--source", str(clip / "video.mp4"), "--can", "virtual:bsn-fs-flip",
                           "--log", str(tmp_path / "a.jsonl")])
        got = statuses(rx)
    assert rc == 2
    err = capsys.readouterr().err
    assert "damaged" in err and "sha256" in err and "UNAVAILABLE sent" in err
    assert got == [SystemState.UNAVAILABLE], "one UNAVAILABLE status before refusing"
    assert not (tmp_path / "a.jsonl").exists(), "no frame ran"
    Engine(SHIPPED)   # the intact file loads and passes its self-test


@pytest.mark.parametrize(("threshold", "says"), [(float("nan"), "'bsn.threshold' is not a card's JSON"),
                                                 (7.0, "threshold must lie in"), (0.0, "threshold must lie in")])
def test_out_of_range_metadata_is_refused_even_with_a_fresh_digest(setup, tmp_path, threshold, says):
    model, _ = setup
    bad = tmp_path / "t.onnx"
    m = onnx.load(str(model))
    props = {p.key: p.value for p in m.metadata_props}
    props["bsn.threshold"] = json.dumps(threshold)
    from bsn_edge.card import CARD_SHA_KEY, card_digest
    props[CARD_SHA_KEY] = card_digest(props)
    del m.metadata_props[:]
    for k, v in props.items():
        e = m.metadata_props.add()
        e.key, e.value = k, v
    onnx.save(m, str(bad))
    with pytest.raises(ModelError, match=says):
        Engine(bad)


def test_an_edited_card_without_its_digest_is_damaged(setup, tmp_path):
    model, _ = setup
    m = onnx.load(str(model))
    for p in m.metadata_props:
        if p.key == "bsn.threshold":
            p.value = "0.9"
    onnx.save(m, str(tmp_path / "e.onnx"))
    with pytest.raises(ModelError, match="metadata is damaged"):
        Engine(tmp_path / "e.onnx")


def test_a_wrong_self_test_answer_refuses_to_start(setup, tmp_path):
    model, _ = setup
    card = Engine(model).card
    st = card.self_test
    shifted = st.__class__(st.grid, tuple(min(p + 0.2, 1.0) for p in st.prob), st.depth, st.prob_atol, st.depth_rtol)
    rewrite_card(model, tmp_path / "s.onnx", self_test=shifted)
    with pytest.raises(ModelError, match=r"self-test failed: probabilities differ by up to 0\.2"):
        Engine(tmp_path / "s.onnx")


def test_an_input_size_that_is_not_the_graphs_is_refused_at_load(setup, tmp_path):
    model, _ = setup
    card = Engine(model).card
    rewrite_card(model, tmp_path / "z.onnx", **{f: getattr(card.at_size(256, 512), f)
                                                  for f in ("input_size", "camera")})
    with pytest.raises(ModelError, match=r"takes tensor\(uint8\) \[1, 128, 256, 3\], its card says .*256x512"):
        Engine(tmp_path / "z.onnx")


def test_a_model_without_a_camera_is_refused_not_guessed(setup, tmp_path):
    model, _ = setup
    m = onnx.load(str(model))
    keep = {p.key: p.value for p in m.metadata_props if p.key not in ("bsn.camera", CARD_SHA_KEY)}
    keep[CARD_SHA_KEY] = card_digest(keep)     # re-digested: the card is intact, only the camera is missing
    del m.metadata_props[:]
    for k, v in keep.items():
        e = m.metadata_props.add()
        e.key, e.value = k, v
    onnx.save(m, str(tmp_path / "c.onnx"))
    with pytest.raises(ModelError, match=r"missing 'bsn\.camera'"):
        Engine(tmp_path / "c.onnx")


# -- a damaged video: skipped stretches, every readable frame used, UNAVAILABLE at the end -------------

def damage(src: Path, dst: Path, start: float, length: float) -> None:
    data = bytearray(src.read_bytes())
    a, n = int(len(data) * start), int(len(data) * length)
    data[a:a + n] = bytes(n)
    dst.write_bytes(bytes(data))


def test_a_video_damaged_in_the_middle_keeps_the_frames_after_the_damage(setup, tmp_path):
    model, clip = setup
    video = long_video(clip, tmp_path / "long.mp4", 4)   # 60 frames
    bad = tmp_path / "bad.mp4"
    damage(video, bad, 0.35, 0.2)
    with can.Bus(interface="virtual", channel="bsn-fs-dmg") as rx, CanSender("virtual", "bsn-fs-dmg") as tx:
        engine = Engine(model)
        summary = run(engine, open_source(str(bad)), [tx], log=tmp_path / "l.jsonl", camera=mounted(engine, clip))
        got = statuses(rx)
    lines = [json.loads(x) for x in (tmp_path / "l.jsonl").read_text().splitlines()]
    broken = [x["frame"] for x in lines if x.get("fault") == "decode_errors"]
    assert broken, "the damage was seen"
    assert summary["frames"] == 60 and summary["valid_frames"] == 60 - len(broken)
    assert max(x["frame"] for x in lines if "levels" in x) == 59, "frames after the damage were used"
    assert summary["source_failure"] is None
    assert SystemState.UNAVAILABLE in got[:-1] and got[-1] == SystemState.UNAVAILABLE
    assert got[0] == SystemState.DEGRADED or got[0] == SystemState.OK


def test_a_video_cut_short_is_a_failed_source_with_a_non_zero_exit(setup, tmp_path, capsys):
    model, clip = setup
    video = long_video(clip, tmp_path / "long.mp4", 2)
    cut = tmp_path / "cut.mp4"
    damage(video, cut, 0.6, 0.37)   # the frame data to the end, not the index after it
    rc = run_cli.main(["--model", str(model), "--source", str(cut), "--can-log", str(tmp_path / "c.log"),
                       "--summary", str(tmp_path / "s.json")])
    assert rc == 1
    assert "the source failed" in capsys.readouterr().err
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["source_failure"] and s["faults"]["decode_errors"] > 0


# -- a stalled live stream: back-off reconnects, UNAVAILABLE while it is gone --------------------------

_yy, _xx = np.mgrid[0:96, 0:192]
SCENE = np.repeat((40 + _yy + 60 * ((_xx // 12) % 2))[..., None], 3, axis=2).astype(np.uint8)


class FlakyCamera:
    """Frames for a while, then nothing (a stall ends in a failed read).

    With ``after`` the first camera's frames go on until that event is set and only then count down,
    so its stall comes while the loop runs, however long the model takes to load on a loaded machine.
    ``delivered`` holds how many frames each opened camera gave."""

    opened = 0
    delivered: ClassVar[list[int]] = []
    GATE_TIMEOUT_S = 30.0

    def __init__(self, _target, frames: int = 12, stall_s: float = 0.0,
                 after: threading.Event | None = None) -> None:
        FlakyCamera.opened += 1
        self.left, self.stall_s, self.n = frames, stall_s, FlakyCamera.opened
        self.rng = np.random.default_rng(self.n)
        self.after, self.since = after, time.monotonic()
        FlakyCamera.delivered.append(0)

    def set(self, *_):
        return True

    def isOpened(self):
        # the first reconnect finds the camera still gone, the second brings it back; after the
        # second loss it never comes back
        return self.n in (1, 3)

    def read(self):
        waiting = self.after is not None and not self.after.is_set() \
            and time.monotonic() - self.since < self.GATE_TIMEOUT_S
        if self.left <= 0:
            time.sleep(self.stall_s)
            return False, None
        if not waiting:
            self.left -= 1
        FlakyCamera.delivered[self.n - 1] += 1
        time.sleep(0.02)
        # a scene, not a flat grey (a camera showing one grey is covered, and says so): stripes and a ramp,
        # with a sensor's noise so that no two frames are the same
        return True, SCENE + self.rng.integers(0, 3, SCENE.shape, dtype=np.uint8)

    def release(self):
        pass


class BusWatch:
    """The statuses heard on a bus, gathered by a thread while the run goes on; ``running`` is set at
    the first one that is not UNAVAILABLE (the loop has made a valid inference)."""

    def __init__(self, rx) -> None:
        self.rx, self.got = rx, []
        self.running, self._stop = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while not self._stop.is_set():
            m = self.rx.recv(timeout=0.05)
            if m is not None and (state := status_of(m)) is not None:
                self.got.append(state)
                if state != SystemState.UNAVAILABLE:
                    self.running.set()

    def close(self) -> list[int]:
        """Stop listening; every status heard, the ones still queued on the bus included."""
        self._stop.set()
        self._thread.join(timeout=2)
        return self.got + statuses(self.rx)


def test_a_stalled_stream_reconnects_and_the_bus_shows_it(setup):
    model, clip = setup
    FlakyCamera.opened, FlakyCamera.delivered = 0, []
    policy = Reconnect(stall_s=0.5, first_s=0.4, max_s=0.8, give_up_s=5.0, max_tries=3)
    cfg = RuntimeConfig(cycle_s=0.05)
    with can.Bus(interface="virtual", channel="bsn-fs-live") as rx, CanSender("virtual", "bsn-fs-live") as tx:
        watch = BusWatch(rx)
        src = LiveSource("rtsp://camera", policy,
                         opener=lambda t: FlakyCamera(t, frames=12, stall_s=0.3, after=watch.running))
        engine = Engine(model)
        summary = run(engine, src, [tx], cfg, camera=mounted(engine, clip))
        got = watch.close()
    src.close()
    assert FlakyCamera.opened >= 3 and summary["faults"]["source_reconnects"] >= 2
    assert FlakyCamera.delivered[1] == 0 and FlakyCamera.delivered[2] == 12
    assert summary["frames"] + summary["dropped"] + summary["before_start"] == sum(FlakyCamera.delivered), \
        "frames came again after the reconnect"
    # OK / DEGRADED while frames come, UNAVAILABLE during the outage (> 0.5 s), again after, and at the end
    changes = [s for i, s in enumerate(got) if i == 0 or s != got[i - 1]]
    assert SystemState.UNAVAILABLE in changes[1:-1] and changes[-1] == SystemState.UNAVAILABLE, changes
    assert summary["source_failure"] and "reconnects failed" in summary["source_failure"]


# -- two threads on one Health, and a heartbeat that survives ------------------------------------------

def test_health_survives_two_threads_hammering_it():
    """Two writers and a reader: every count lands (a counter bumped without the lock loses some once
    threads switch often, which the short switch interval makes happen within the test)."""
    h = Health(HealthConfig(window_s=0.5))      # the shortest window: 50 inferences in it
    errors: list[BaseException] = []
    n = 20000

    def writer():
        try:
            for i in range(n):
                h.valid(i * 1e-2)
                h.fault("decode_errors")
                h.set_fault("dropped_frames", i)
        except BaseException as e:
            errors.append(e)

    def reader():
        try:
            for i in range(n):
                h.snapshot(i * 1e-2)
                h.fps(i * 1e-2)
                _ = h.faults
        except BaseException as e:
            errors.append(e)

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        threads = [threading.Thread(target=writer), threading.Thread(target=writer), threading.Thread(target=reader)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(old)
    assert not errors
    assert h.faults["decode_errors"] == 2 * n and h.faults["dropped_frames"] == n - 1


class ExplodingHealth(Health):
    """A health whose snapshot raises now and then: a bug the heartbeat must outlive."""

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def snapshot(self, t):
        self.calls += 1
        if self.calls % 3 == 1:
            raise RuntimeError("deque mutated during iteration")
        return super().snapshot(t)


def test_the_heartbeat_counts_an_exception_and_keeps_sending():
    h = ExplodingHealth()
    with can.Bus(interface="virtual", channel="bsn-fs-hb") as rx, CanSender("virtual", "bsn-fs-hb") as tx:
        emitter = CycleEmitter([tx], h, cycle_s=0.02)
        with Heartbeat(emitter) as hb:
            deadline = time.monotonic() + 5
            while emitter.sent_cycles < 5 and time.monotonic() < deadline:
                time.sleep(0.01)
        got = statuses(rx)
    assert emitter.sent_cycles >= 5 and len(got) >= 5
    assert h.faults["heartbeat_errors"] >= 1 and "deque mutated" in hb.last_error


# -- SIGTERM stops like SIGINT: logs, summary and the last UNAVAILABLE are kept -------------------------

def test_sigterm_keeps_the_logs_the_summary_and_sends_unavailable(setup, tmp_path):
    model, clip = setup
    video = long_video(clip, tmp_path / "long.mp4", 20)   # 300 frames, 30 s paced
    log, canlog, summ = tmp_path / "a.jsonl", tmp_path / "a.log", tmp_path / "s.json"
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    proc = subprocess.Popen([sys.executable, "-m", "bsn_edge.cli.run", "--model", str(model), "--source", str(video),
                             "--pace", "--log", str(log), "--can-log", str(canlog), "--summary", str(summ)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not log.exists() or len(log.read_text().splitlines()) < 3):
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    summary = json.loads(summ.read_text())
    assert summary["signal"] == "SIGTERM" and summary["stopped"] and 3 <= summary["frames"] < 300
    assert out.startswith(f"bsn-run: {summary['frames']} frames"), out
    lines = log.read_text().splitlines()
    assert len(lines) == summary["frames"] and all(json.loads(x) for x in lines)
    msgs = list(can.LogReader(str(canlog)))
    st = [decode(m.arbitration_id, bytes(m.data)) for m in msgs]
    st = [d for d in st if d is not None and d.name == "BSN_Status"]
    assert st and st[-1].crc_ok and st[-1].signals["System_State"] == SystemState.UNAVAILABLE


def test_a_can_log_bsn_listen_cannot_read_is_refused_before_anything_runs(setup, tmp_path, capsys):
    model, clip = setup
    assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--can-log",
                         str(tmp_path / "alerts.txt"), "--log", str(tmp_path / "a.jsonl")]) == 2
    assert ".log, .asc, .blf" in capsys.readouterr().err and not (tmp_path / "a.jsonl").exists()


def test_a_missing_can_interface_is_named(setup, capsys):
    model, clip = setup
    assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--can", "nosuchbus:x"]) == 2
    assert "cannot open CAN interface 'nosuchbus' channel 'x'" in capsys.readouterr().err


def test_a_serial_port_gone_for_good_is_degraded_on_the_other_bus_and_a_non_zero_exit(setup, capsys, monkeypatch):
    """The serial port vanishes and cannot be reopened: after a second of failed sends it is down, the
    CAN bus (decoded with cantools from the DBC, not the project's decoder) says DEGRADED, the summary
    names it, and bsn-run's ending says so with exit 1."""
    import cantools

    from bsn_edge.alerts.serial_output import SerialSender
    from bsn_edge.cli.common import CHECKOUT as ROOT
    from tests.fakes import GonePort
    model, clip = setup
    dbc = cantools.database.load_file(str(ROOT / "bsn_edge" / "alerts" / "bsn_alerts.dbc"))
    serial_tx = SerialSender("/dev/bsn-no-such-port", port=GonePort(), retry_s=0.0)
    with can.Bus(interface="virtual", channel="bsn-fs-serial") as rx, \
            CanSender("virtual", "bsn-fs-serial") as can_tx:
        engine = Engine(model)
        summary = run(engine, open_source(str(clip / "video.mp4")), [can_tx, serial_tx],
                      RuntimeConfig(cycle_s=0.05), camera=mounted(engine, clip))
        states = [dbc.decode_message(m.arbitration_id, bytes(m.data))["System_State"]
                  for m in iter(lambda: rx.recv(0.2), None) if m.arbitration_id == 0x501]
    serial_tx.close()
    assert summary["senders_down"] == ["serial"] and summary["senders"]["serial"]["errors"] > 10
    names = [str(s) for s in states]
    assert "DEGRADED" in names and names[-1] == "UNAVAILABLE"
    assert "OK" not in names[names.index("DEGRADED"):], "it stays down: DEGRADED until the end"
    # the command line: the same port gone, exit 1 and the reason at the end
    monkeypatch.setattr(run_cli, "make_senders", lambda args, bus=None, sectors=None: [
        SerialSender("/dev/bsn-no-such-port", port=GonePort(), retry_s=0.0)])
    rc = run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                       str(clip / "calibration.json")])
    assert rc == 1 and "serial could not send at the end of the run" in capsys.readouterr().err


def test_beside_every_unavailable_status_the_hazard_says_nothing_is_known():
    """A WARNING on the left at 4.5 m, then no valid inference past the deadline: from then every hazard
    frame (decoded with cantools from the DBC) carries levels NONE, scores 0 and the far distance 63.5,
    never the last WARNING; the final cycle too."""
    db = cantools.database.load_file(str(DBC_PATH))
    h = Health(HealthConfig(deadline_s=0.5, fps_floor=0.0))    # one inference: the rate is no fault here
    warn = SectorAlert(1.0, Level.WARNING, 4.5)
    with can.Bus(interface="virtual", channel="bsn-fs-unav") as rx, CanSender("virtual", "bsn-fs-unav") as tx:
        emitter = CycleEmitter([tx], h, cycle_s=0.1)
        h.valid(0.0)
        emitter.publish(AlertFrame(0.0, (warn,) * 3, SystemState.OK, 20.0, {}))
        emitter.emit(0.0)
        emitter.emit(1.5)                    # deadline 0.5 s: cycles 0.0 .. 0.5 OK, 0.6 .. 1.5 UNAVAILABLE
        h.unavailable()
        emitter.final(1.55)
        msgs = [db.decode_message(m.arbitration_id, bytes(m.data)) | {"id": m.arbitration_id}
                for m in iter(lambda: rx.recv(0.2), None)]
    pairs = list(zip(msgs[0::2], msgs[1::2], strict=True))
    assert all(hz["id"] == 0x500 and st["id"] == 0x501 for hz, st in pairs) and len(pairs) == 17
    states = [str(st["System_State"]) for _, st in pairs]
    assert states == ["OK"] * 6 + ["UNAVAILABLE"] * 11
    for hz, st in pairs:
        for side in ("Left", "Centre", "Right"):
            if str(st["System_State"]) == "UNAVAILABLE":
                assert str(hz[f"{side}_Level"]) == "NONE" and hz[f"{side}_Score"] == 0
                assert hz[f"{side}_Distance"] == 63.5
            else:
                assert str(hz[f"{side}_Level"]) == "WARNING" and hz[f"{side}_Distance"] == 4.5
