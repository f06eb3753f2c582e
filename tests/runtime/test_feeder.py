"""Reading overlapped with the model: every frame from a file, the newest from a live source, no buffer
written while the model reads it, and the loop's answers the same as reading in turn."""

import json
import os
import threading
import time

import numpy as np
import pytest

from bsn_edge.runtime import Engine, RuntimeConfig, open_source, run
from bsn_edge.runtime.feeder import Feeder
from bsn_edge.runtime.sources import Captured, Source
from tests.fakes import StepClock, mounted


class ListSource(Source):
    """Frames filled with their index, ``gap_s`` apart; ``live`` like a camera (its frame times on the
    processing clock, as a camera's are)."""

    def __init__(self, n: int, live: bool = False, gap_s: float = 0.0, shape=(4, 6, 3)) -> None:
        super().__init__()
        self.n, self.live, self.gap_s, self.shape = n, live, gap_s, shape

    def _frames(self):
        for i in range(self.n):
            if self.gap_s:
                time.sleep(self.gap_s)
            t = time.monotonic() if self.live else 0.1 * i
            yield Captured(t, np.full(self.shape, i % 256, np.uint8), i)


def copy_warp(cap, buf):
    """A warp that writes the frame's value into the whole buffer, slowly enough to race the model."""
    time.sleep(0.002)
    buf[...] = cap.frame[0, 0, 0]
    return None, False


def buffers(n=3):
    return [np.zeros((1, 4, 6, 3), np.uint8) for _ in range(n)]


def test_from_a_file_every_frame_in_order_and_no_buffer_written_while_read():
    feeder = Feeder(ListSource(40), copy_warp, buffers(), background=True)
    seen = []
    for item in feeder:
        time.sleep(0.005)                 # the model is busy; the feeder runs as far ahead as it may
        # what the model reads is still the frame it was given, not one warped since
        assert (item.buf == item.cap.index).all(), item.cap.index
        seen.append(item.cap.index)
        feeder.release(item.buf)
    feeder.close()
    assert seen == list(range(40)) and feeder.dropped == 0


def test_from_a_live_source_the_newest_frame_wins_and_the_rest_are_counted():
    feeder = Feeder(ListSource(60, live=True, gap_s=0.001), copy_warp, buffers(), background=True)
    seen = []
    for item in feeder:
        time.sleep(0.02)
        assert (item.buf == item.cap.index).all()
        seen.append(item.cap.index)
        feeder.release(item.buf)
    feeder.close()
    assert seen == sorted(seen) and seen[-1] == 59, "in order, and the last frame is never lost"
    assert feeder.dropped > 0 and feeder.dropped == 60 - len(seen)


def test_at_most_limit_frames_and_errors_reach_the_caller():
    feeder = Feeder(ListSource(10), copy_warp, buffers(), background=True, limit=4)
    assert [i.cap.index for i in feeder] == [0, 1, 2, 3], "buffers come back when the next frame is asked for"

    def failing(cap, buf):
        if cap.frame[0, 0, 0] == 3:
            raise RuntimeError("the warp failed")
        return copy_warp(cap, buf)

    feeder, seen = Feeder(ListSource(10), failing, buffers(), background=True), []
    with pytest.raises(RuntimeError, match="the warp failed"):
        for item in feeder:
            seen.append(item.cap.index)
            feeder.release(item.buf)
    assert seen == [0, 1, 2], "the frames before the failure are delivered first"
    with pytest.raises(ValueError, match="3 input buffers"):
        Feeder(ListSource(1), copy_warp, buffers(2), background=True)


class DamagedSource(ListSource):
    """Frames ``bad`` do not decode (no picture), as in a video damaged in the middle."""

    def __init__(self, n: int, bad: range) -> None:
        super().__init__(n)
        self.bad = bad

    def __iter__(self):
        for cap in super().__iter__():
            yield Captured(cap.t, None, cap.index) if cap.index in self.bad else cap


def test_a_run_of_undecodable_frames_longer_than_the_buffers_goes_through():
    """Every frame is delivered in order, the ones without a picture too, however many of them come
    in a row (each must give its input buffer back, or the feeder runs out of them)."""
    feeder = Feeder(DamagedSource(20, range(3, 3 + 2 * Feeder.BUFFERS)), copy_warp, buffers(), background=True)
    seen = []

    def consume():
        for item in feeder:
            seen.append((item.cap.index, item.buf is None, None if item.buf is None else int(item.buf[0, 0, 0, 0])))

    reader = threading.Thread(target=consume, daemon=True)
    reader.start()
    reader.join(timeout=30)
    stuck = reader.is_alive()
    feeder.close()
    assert not stuck, f"the feeder stopped delivering after frame {seen[-1][0] if seen else None}"
    assert seen == [(i, 3 <= i < 3 + 2 * Feeder.BUFFERS, None if 3 <= i < 3 + 2 * Feeder.BUFFERS else i)
                    for i in range(20)]


@pytest.mark.skipif(not hasattr(os, "setpriority"), reason="thread priorities are Linux's")
def test_a_nice_feeder_reads_below_the_callers_priority():
    """The warp runs on the feeder's thread: its priority, read from the system, is ``nice`` below the
    caller's, whose own is untouched."""
    seen = {}

    def warp(cap, buf):
        tid = threading.get_native_id()
        seen[tid] = os.getpriority(os.PRIO_PROCESS, tid)
        return copy_warp(cap, buf)

    me = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    assert len(list(Feeder(ListSource(3), warp, buffers(), background=True, nice=5))) == 3
    assert list(seen.values()) == [min(19, me + 5)]
    assert threading.get_native_id() not in seen
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == me
    with pytest.raises(ValueError, match="nice"):
        Feeder(ListSource(1), copy_warp, buffers(), background=True, nice=20)
    with pytest.raises(ValueError, match="feeder_nice"):
        RuntimeConfig(feeder_nice=-1)


def frame_log(path):
    timed = ("latency_ms", "stage_ms")
    return [{k: v for k, v in json.loads(x).items() if k not in timed} for x in path.read_text().splitlines()]


@pytest.mark.parametrize("calibrating", [False, True])
def test_overlap_changes_no_answer(setup, tmp_path, calibrating):
    """The same frames, the same alerts, the same maps, with reading overlapped or in turn (and while
    calibrating online, whose estimate is adopted at the same frame either way)."""
    model, clip = setup
    out = {}
    for overlap in (False, True):
        engine = Engine(model)
        camera = None if calibrating else mounted(engine, clip)
        log, maps = tmp_path / f"log{overlap}.jsonl", tmp_path / f"maps{overlap}"
        # on a clock the machine's speed does not move: a stall under load would change the state logged
        summary = run(engine, open_source(str(clip / "video.mp4")), [], RuntimeConfig(overlap=overlap),
                      log=log, camera=camera, save_maps=maps, clock=StepClock())
        assert summary["overlap"] is overlap and summary["frames"] == 15 and summary["dropped"] == 0
        out[overlap] = frame_log(log), {p.name: p.read_bytes() for p in sorted(maps.iterdir())}
    assert out[True][0] == out[False][0]
    assert out[True][1] == out[False][1] and len(out[True][1]) == 30


class SlowEngine(Engine):
    def infer(self, batch):
        time.sleep(0.03)
        return super().infer(batch)


def test_frames_the_model_had_no_time_for_are_a_fault_on_the_bus(setup):
    model, _ = setup
    engine = SlowEngine(model)
    h, w = engine.size
    summary = run(engine, ListSource(40, live=True, gap_s=0.003, shape=(h, w, 3)), [],
                  RuntimeConfig(warmup=0, overlap=True))
    assert summary["dropped"] > 0 and summary["frames"] + summary["dropped"] == 40
    assert summary["faults"]["dropped_frames"] == summary["dropped"]


@pytest.mark.parametrize("calibrating", [False, True])
def test_two_frames_in_flight_change_no_answer(setup, tmp_path, calibrating):
    """Two inferences side by side on one-thread engines: the same frames, alerts and maps, in the same
    order, as one at a time."""
    model, clip = setup
    out = {}
    for in_flight in (1, 2):
        engine = Engine(model, threads=3 - in_flight)
        camera = None if calibrating else mounted(engine, clip)
        log, maps = tmp_path / f"log{in_flight}.jsonl", tmp_path / f"maps{in_flight}"
        summary = run(engine, open_source(str(clip / "video.mp4")), [], RuntimeConfig(in_flight=in_flight),
                      log=log, camera=camera, save_maps=maps, clock=StepClock())
        assert summary["in_flight"] == in_flight and summary["frames"] == 15 and summary["dropped"] == 0
        out[in_flight] = frame_log(log), {p.name: p.read_bytes() for p in sorted(maps.iterdir())}
    assert [r["frame"] for r in out[2][0]] == list(range(15))
    assert out[2][0] == out[1][0] and out[2][1] == out[1][1]


def test_frames_in_flight_stop_at_max_frames_and_need_overlap(setup):
    model, clip = setup
    summary = run(Engine(model, threads=1), open_source(str(clip / "video.mp4")), [], RuntimeConfig(in_flight=2),
                  max_frames=6)
    assert summary["frames"] == 6 and summary["valid_frames"] == 6
    with pytest.raises(ValueError, match="overlap"):
        RuntimeConfig(in_flight=2, overlap=False)
    with pytest.raises(ValueError, match="in_flight"):
        RuntimeConfig(in_flight=0)
    with pytest.raises(ValueError, match="4 input buffers"):
        Feeder(ListSource(3), lambda f, b: (None, False), [np.empty(1)] * 3, background=True, held=2)
