"""Each stage of the runtime's way on its own, against what it must do (not a run end to end): decode counts
what the source says, the warp shows the frame to calibration and then puts the frame into the model camera,
inference refuses NaN, postprocess turns a mask into levels, send sends the cycles due, outputs feeds the
writers; and the pipeline times every stage it runs into the frame's stage_ms."""

import numpy as np
import pytest

from bsn_edge.alerts import SystemState
from bsn_edge.alerts.can_codec import decode
from bsn_edge.alerts.health import Fault
from bsn_edge.alerts.senders import Sender
from bsn_edge.alerts.state_machine import Level
from bsn_edge.calibration import Calibration
from bsn_edge.runtime import Engine, RuntimeConfig
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.frame_record import FrameRecord
from bsn_edge.runtime.loop import FramePipeline, Outputs
from bsn_edge.runtime.sources import Captured, ImageFolderSource


class Collect(Sender):
    """A sender that keeps what it sends, decoded back."""

    name = "collect"

    def __init__(self) -> None:
        super().__init__()
        self.got = []

    def _send(self, frames):
        self.got += [decode(fid, data) for fid, data in frames]


@pytest.fixture
def pipeline(setup):
    model, clip = setup
    engine = Engine(model)
    camera = CameraState(engine.card, Calibration.read(clip / "calibration.json"))
    sender = Collect()
    p = FramePipeline(engine, ImageFolderSource(clip / "rgb"), [sender], RuntimeConfig(cycle_s=0.1), camera,
                      Outputs(), clock=lambda: 0.0)
    yield p, sender, clip
    camera.close()


def test_read_counts_a_frame_that_did_not_decode_and_a_change_of_size(pipeline):
    p, _, _ = pipeline
    rec = FrameRecord(0, 0.0)
    assert not p.stage("decode").read(Captured(0.0, None, 0), rec) and rec.fault is Fault.DECODE_ERRORS
    rec = FrameRecord(1, 0.1)
    assert p.stage("decode").read(Captured(0.1, np.zeros((96, 192, 3), np.uint8), 1), rec) and rec.fault is None
    rec = FrameRecord(2, 0.2)
    assert not p.stage("decode").read(Captured(0.2, np.zeros((90, 192, 3), np.uint8), 2), rec), \
        "a frame of another size than the source's is not run (it would be stretched)"
    assert rec.fault is Fault.SIZE_CHANGES
    rec = FrameRecord(3, 0.3)
    assert p.stage("decode").read(Captured(0.3, np.zeros((96, 192, 3), np.uint8), 3), rec) and rec.fault is None
    assert p.health.faults[Fault.DECODE_ERRORS] == 1 and p.health.faults[Fault.SIZE_CHANGES] == 1
    assert p.frames == 4


def test_warp_puts_the_frame_into_the_model_camera_as_the_camera_file_says(pipeline):
    import cv2
    p, _, clip = pipeline
    frame = cv2.imread(str(sorted((clip / "rgb").glob("*.png"))[0]))
    buf = np.empty_like(p.engine.buf)
    _, calibrating = p.warp(Captured(0.0, frame, 0), buf)
    assert not calibrating, "the camera file has a mounting"
    cal = Calibration.read(clip / "calibration.json")
    want = cal.model_frame(frame.shape[1], frame.shape[0], p.engine.card.camera, p.engine.card.mounting).to_model(frame)
    assert np.array_equal(buf[0], want)


def test_frame_for_changes_nothing_and_observe_is_what_calibrates(setup):
    import cv2
    model, clip = setup
    engine = Engine(model)
    state = CameraState(engine.card, None, background=False)
    frame = cv2.imread(str(sorted((clip / "rgb").glob("*.png"))[0]))
    for _ in range(3):
        state.frame_for(frame)
    assert state._calibrator is None, "asking for the model frame starts no estimator"
    state.observe(frame)
    assert state._calibrator is not None and state._calibrator.seen == 1
    state.close()


def test_checked_refuses_nan_and_infinity_and_counts_them(pipeline):
    p, _, _ = pipeline
    h, w = p.engine.card.input_size
    good = (np.full((h, w), 0.2, np.float32), np.full((h, w), 10.0, np.float32))
    assert p.stage("inference").checked(*good) is not None
    bad_p = good[0].copy()
    bad_p[3, 4] = np.nan
    bad_d = good[1].copy()
    bad_d[0, 0] = np.inf
    assert p.stage("inference").checked(bad_p, good[1]) is None and p.stage("inference").checked(good[0], bad_d) is None
    assert p.health.faults[Fault.NAN_OUTPUTS] == 2


def test_sectors_turn_a_near_blind_spot_on_the_left_into_a_left_warning(pipeline):
    import cv2
    p, _, clip = pipeline
    frame = cv2.imread(str(sorted((clip / "rgb").glob("*.png"))[0]))
    mf = p.camera.frame_for(frame)
    h, w = p.engine.card.input_size
    prob = np.zeros((h, w), np.float32)
    prob[int(0.7 * h):, : w // 4] = 1.0            # low in the picture on the left: near road hidden
    depth = np.full((h, w), 4.0, np.float32)
    alert = None
    for k in range(20):                             # smoothing: levels rise over frames, not at once
        alert, mask = p.stage("postprocess").read(Captured(0.1 * k, frame, k), mf, prob, depth)
    left, centre, right = alert.sectors
    assert left.level is Level.WARNING and centre.level is Level.NONE and right.level is Level.NONE
    assert left.distance_m is not None and left.distance_m < 8.0
    assert mask[int(0.8 * h), 2] and p.emitter.latest is alert, "published to the send cycle"


def test_emit_sends_every_cycle_due_by_the_frames_time(pipeline):
    p, sender, _ = pipeline
    p.stage("send").emit(Captured(0.0, None, 0))
    p.stage("send").emit(Captured(0.35, None, 1))
    status = [d for d in sender.got if d.name == "BSN_Status"]
    assert len(status) == 4, "cycles at 0.0, 0.1, 0.2 and 0.3 s"
    assert all(d.crc_ok for d in sender.got)
    assert status[0].signals["System_State"] == SystemState.UNAVAILABLE, "no valid inference yet"


def test_write_hands_the_frame_to_each_output_that_is_still_writing(pipeline):
    from bsn_edge.runtime.sinks import GuardedSink
    p, _, _ = pipeline
    got = {"overlay": [], "maps": []}
    p.sinks["overlay"] = GuardedSink("overlay", lambda *a: got["overlay"].append(a))
    p.sinks["maps"] = GuardedSink("maps", lambda *a: got["maps"].append(a))
    h, w = p.engine.card.input_size
    frame = np.zeros((96, 192, 3), np.uint8)
    mf = p.camera.frame_for(frame)
    zeros, ones = np.zeros((h, w), np.float32), np.ones((h, w), np.float32)
    alert, mask = p.stage("postprocess").read(Captured(0.0, frame, 0), mf, zeros, ones)
    p.stage("outputs").write(Captured(0.0, frame, 0, name="a"), mf, mask, alert, np.zeros((h, w), np.float32),
            np.ones((h, w), np.float32))
    for sink in p.sinks.values():
        sink.close()
    assert len(got["overlay"]) == 1 and got["overlay"][0][0] is frame
    assert len(got["maps"]) == 1 and got["maps"][0][0] == "a"


def test_a_camera_that_reconnects_at_another_size_runs_at_its_new_size(pipeline):
    """A live camera reopened (``reconnects`` moves on) may come back at another resolution: its size is
    learnt again from its first frame, so its frames run; a frame of the old size after that is the odd one."""
    p, _, _ = pipeline
    old, new = np.zeros((96, 192, 3), np.uint8), np.zeros((120, 160, 3), np.uint8)
    assert p.stage("decode").read(Captured(0.0, old, 0), FrameRecord(0, 0.0))
    rec = FrameRecord(1, 0.1)
    read = p.stage("decode").read
    assert not read(Captured(0.1, new, 1), rec) and rec.fault is Fault.SIZE_CHANGES   # same camera: damaged
    p.source.reconnects += 1
    for i in range(2, 6):
        rec = FrameRecord(i, 0.1 * i)
        assert read(Captured(0.1 * i, new, i), rec) and rec.fault is None, f"frame {i} after the reconnect"
    buf = np.zeros((1, *p.engine.size, 3), np.uint8)
    _, calibrating = p.warp(Captured(0.5, np.full((120, 160, 3), 128, np.uint8), 5), buf)     # warped at its new size
    assert buf.any() and not calibrating
    rec = FrameRecord(6, 0.6)
    assert not p.stage("decode").read(Captured(0.6, old, 6), rec) and rec.fault is Fault.SIZE_CHANGES
    assert p.health.faults[Fault.SIZE_CHANGES] == 2


def test_the_frame_log_and_the_overlay_say_the_state_that_went_on_the_bus(setup):
    """The status is decided once, by the send cycle. A processing clock that now and then runs on past the
    deadline between one look and the next made the loop's own look say one state while the cycle sent
    another; now every log line and overlay frame carries the state of the last status on the bus."""
    import itertools
    import time

    from bsn_edge.runtime.feeder import Prepared

    class Keep:
        ok = True

        def __init__(self):
            self.got = []

        def check(self):
            return True

        def write(self, frame, *args):
            self.got.append(args)

    model, clip = setup
    engine = Engine(model)
    camera = CameraState(engine.card, Calibration.read(clip / "calibration.json"))
    sender = Collect()
    steps = itertools.cycle([0.01, 0.01, 0.01, 0.6])    # seconds the processing clock moves at each look
    now = itertools.accumulate(steps)
    p = FramePipeline(engine, ImageFolderSource(clip / "rgb"), [sender], RuntimeConfig(cycle_s=0.1), camera,
                      Outputs(), clock=lambda: next(now))
    p.sinks = {"log": Keep(), "overlay": Keep()}
    seen = set()
    for cap in itertools.islice(p.source, 12):
        buf = np.empty_like(engine.buf)
        mf, calibrating = p.warp(cap, buf)
        p.step(Prepared(cap, mf, buf, calibrating, 0.0, time.perf_counter()))
        on_bus = SystemState([d for d in sender.got if d.name == "BSN_Status"][-1].signals["System_State"])
        (line,), (*_, alert) = p.sinks["log"].got[-1], p.sinks["overlay"].got[-1]
        assert line["state"] == on_bus.name and alert.state is on_bus, cap.index
        seen.add(on_bus)
    camera.close()
    assert SystemState.UNAVAILABLE in seen and len(seen) > 1, "the clock made the state change on the way"


def test_the_pipeline_times_each_stage_it_runs_and_after_a_stop_only_those_that_always_run(pipeline):
    """The way is a list of stage objects; the pipeline, not the stage, writes each one's time into the totals and
    the frame's stage_ms: the seconds a stage says its work took on another thread when it says one (checked to
    the digit), its own run's otherwise. A stage that ends the frame's way stops the rest but the send cycle."""
    from bsn_edge.runtime.feeder import Prepared
    from bsn_edge.runtime.stages import STAGES, Stage, Work

    p, _, _ = pipeline
    ran = []

    def stage(name: str, goes: bool, away: float | None, always: bool = False) -> Stage:
        class Fake(Stage):
            def run(self, w: Work) -> bool:
                ran.append(name)
                return goes

            def elsewhere(self, w: Work) -> float | None:
                return away

        Fake.name, Fake.always = name, always
        return Fake(p)

    p.stages = (stage("decode", True, 0.25), stage("preprocess", False, None), stage("visibility", True, 1.0),
                stage("send", True, 0.5, always=True))
    w = Work(Prepared(Captured(0.0, None, 0), None, None, False, 0.0, 0.0), FrameRecord(0, 0.0))
    p.through(w)
    assert ran == ["decode", "preprocess", "send"], "visibility is past the stop; send runs for every frame"
    assert w.rec.stage_ms["decode"] == 250.0 and w.rec.stage_ms["send"] == 500.0
    assert 0 <= w.rec.stage_ms["preprocess"] < 1000 and "visibility" not in w.rec.stage_ms
    assert p.timer.seconds["decode"] == 0.25 and p.timer.seconds["visibility"] == 0.0
    assert {st.name for st in FramePipeline(p.engine, p.source, [], p.cfg, p.camera, Outputs(),
                                            clock=lambda: 0.0).stages} == set(STAGES)
