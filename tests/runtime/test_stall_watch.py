"""A file's or folder's run keeps the bus alive on the wall clock while the loop is stuck on a frame.

A file's cycles go out by its frames' times, which stand still while one frame takes long (a huge picture,
a slow disk, a slow model). The stall watch sends a status after the health deadline of silence, then one
every cycle, and the state it reads is UNAVAILABLE: the deadline holds on the processing clock too.
The bounds are hand-worked: a stall is found at most half a cycle (a wake) after ``after_s``.
"""

import itertools
import threading
import time

import can
import numpy as np

from bsn_edge.alerts import SystemState
from bsn_edge.alerts.can_codec import STATUS, decode
from bsn_edge.alerts.can_output import CanSender
from bsn_edge.alerts.health import Health, HealthConfig
from bsn_edge.alerts.senders import Sender
from bsn_edge.runtime import Engine, RuntimeConfig, open_source, run
from bsn_edge.runtime.cycle import CycleEmitter, StallWatch
from tests.fakes import SimClock, long_video, mounted


class Stamped(Sender):
    """Keeps the simulated time and the state of each status frame."""

    name = "stamped"

    def __init__(self, clock: SimClock) -> None:
        super().__init__()
        self.clock, self.sent = clock, []

    def _send(self, frames):
        for i, d in frames:
            m = decode(i, d)
            if m.name == STATUS:
                self.sent.append((self.clock(), int(m.signals["System_State"])))


def test_the_health_deadline_holds_on_the_processing_clock():
    h = Health(HealthConfig(deadline_s=0.5, fps_floor=0.0))
    h.valid(3.0, 100.0)
    assert h.state(3.0, 100.4) == SystemState.OK
    assert h.state(3.0, 100.6) == SystemState.UNAVAILABLE      # the file's time stood still, the clock did not
    assert h.state(3.6, 100.1) == SystemState.UNAVAILABLE      # and the file's own deadline still holds


def test_a_stuck_loop_gets_a_status_after_the_deadline_then_every_cycle_each_unavailable():
    clock = SimClock(until=3.0)
    sender = Stamped(clock)
    health = Health(HealthConfig(deadline_s=0.5, fps_floor=0.0))
    emitter = CycleEmitter([sender], health, 0.1, clock)
    health.valid(0.0, clock())
    emitter.emit(0.0)                                # the last cycle the loop sent before it got stuck
    StallWatch(emitter, after_s=0.5, wait=clock.wait).run()     # on this thread, on the simulated clock
    times = [t for t, _ in sender.sent]
    assert times[0] == 100.0
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert 0.5 <= gaps[0] <= 0.5 + 0.05 + 1e-9, gaps[0]
    assert all(0.1 - 1e-9 <= g <= 0.15 + 1e-9 for g in gaps[1:]), gaps
    assert [s for _, s in sender.sent[1:]] == [SystemState.UNAVAILABLE] * (len(times) - 1)
    assert emitter.stall_cycles == len(times) - 1 and emitter.stalling


def test_the_watch_is_quiet_while_the_loop_sends():
    clock = SimClock(until=2.0)
    sender = Stamped(clock)
    health = Health(HealthConfig(deadline_s=0.5, fps_floor=0.0))
    emitter = CycleEmitter([sender], health, 0.1, clock)
    watch = StallWatch(emitter, after_s=0.5)
    t = 0.0
    while clock.now < clock.until:              # the loop: a frame every 0.3 s of the clock, 0.1 s of file
        health.valid(t, clock())
        emitter.emit(t)
        watch.beat()
        clock.wait(0.3)
        t += 0.1
    assert emitter.stall_cycles == 0
    assert all(s == SystemState.OK for _, s in sender.sent)


class SlowOnce(Engine):
    """The model takes ``stall_s`` on its ``at``-th frame (a slow frame, disk or model)."""

    def __init__(self, *args, at: int = 6, stall_s: float = 1.6, **kw) -> None:
        self.calls, self.at, self.stall_s = 0, at, stall_s
        super().__init__(*args, **kw)      # its self-test and warm-up infer too
        self.calls = 0

    def infer(self, batch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.calls += 1
        if self.calls == self.at:
            time.sleep(self.stall_s)
        return super().infer(batch)


def test_a_video_stuck_on_one_frame_keeps_the_bus_alive_and_says_unavailable(setup, tmp_path):
    model, clip = setup
    video = long_video(clip, tmp_path / "long.mp4", 2)
    heard: list[tuple[float, int]] = []
    stop = threading.Event()
    with can.Bus(interface="virtual", channel="bsn-stall", receive_own_messages=False) as rx, \
            CanSender("virtual", "bsn-stall") as tx:

        def listen() -> None:
            while not stop.is_set():
                m = rx.recv(timeout=0.02)
                if m is not None and (d := decode(m.arbitration_id, m.data)) is not None and d.name == STATUS:
                    heard.append((time.monotonic(), int(d.signals["System_State"])))

        listener = threading.Thread(target=listen, daemon=True)
        listener.start()
        try:
            engine = SlowOnce(model)
            cfg = RuntimeConfig(cycle_s=0.1, warmup=0, health=HealthConfig(deadline_s=0.5, fps_floor=0.0))
            summary = run(engine, open_source(str(video)), [tx], cfg, camera=mounted(engine, clip))
            time.sleep(0.2)
        finally:
            stop.set()
            listener.join(timeout=2)
    times = [t for t, _ in heard]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert max(gaps) < 1.0, f"the bus was silent for {max(gaps):.2f} s"
    assert summary["stall_cycles"] >= 5
    states = [s for _, s in heard]
    first_ok = states.index(SystemState.OK)
    assert SystemState.UNAVAILABLE in states[first_ok:-1], "the stall was said on the bus"
    assert summary["valid_frames"] == summary["frames"]
