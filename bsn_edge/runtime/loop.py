"""The edge loop: frame -> fused model -> sectors -> smoothing -> alert state -> senders.

Never falls over: an undecodable frame, a frame of another size, NaN in the output or a
failing sender is counted (status message and log), and the loop goes on. Never looks healthy
when it is not: whatever ends the run, the last status on every bus is UNAVAILABLE.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.alerts import AlertFrame, SectorGeometry, SectorState
from bsn_edge.alerts.health import Fault, Health
from bsn_edge.alerts.senders import Sender
from bsn_edge.model_frame import ModelFrame
from bsn_edge.runtime.camera_state import CAMERA_FILE, CameraState
from bsn_edge.runtime.cpu import CpuMeter
from bsn_edge.runtime.cycle import CycleEmitter, Heartbeat, StallWatch
from bsn_edge.runtime.engine import Engine
from bsn_edge.runtime.feeder import Feeder, Prepared
from bsn_edge.runtime.frame_record import FrameRecord
from bsn_edge.runtime.maps import MapWriter
from bsn_edge.runtime.overlay import OverlayWriter, draw
from bsn_edge.runtime.run_summary import ModelSummary, RunSummary, SinkSummary
from bsn_edge.runtime.settings import RuntimeConfig
from bsn_edge.runtime.sinks import GuardedSink, LineLog, SinkFailure, open_all
from bsn_edge.runtime.sources import Captured, Source
from bsn_edge.runtime.stages import STAGES, WAY, Stage, Work
from bsn_edge.runtime.stats import LatencyStats
from bsn_edge.runtime.visibility import BlindnessLog, CameraHealth

__all__ = ["STAGES", "FramePipeline", "Outputs", "StageTimer", "run"]


@dataclass
class Outputs:
    """What a run writes beside the bus: the overlay video, the per-frame JSON log, the maps."""

    overlay: str | Path | None = None
    log: str | Path | None = None
    maps: MapWriter | None = None


class StageTimer:
    """Seconds spent per stage of the frame pipeline (``STAGES``), accumulated over the run."""

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(STAGES, 0.0)

    def add(self, stage: str, seconds: float) -> None:
        self.seconds[stage] += seconds

    def per_frame_ms(self, frames: int) -> dict[str, float]:
        return {k: 1e3 * v / max(frames, 1) for k, v in self.seconds.items()}

    def shares(self) -> dict[str, float]:
        total = sum(self.seconds.values()) or 1.0
        return {k: v / total for k, v in self.seconds.items()}


class FramePipeline:
    """The runtime's work on one source: its state, and the frame's way as a list of stage objects
    (:data:`~bsn_edge.runtime.stages.WAY`: decode, the camera, visibility, inference, sectors, send, outputs),
    each timed into ``stage_ms`` by :meth:`through`; :meth:`run` drives it, :func:`run` wires it.

    Only the warp (:meth:`warp`, into the model camera and an input buffer) runs on the feeder's thread when
    reading overlaps the model (:class:`~bsn_edge.runtime.feeder.Feeder`), and an inference in flight on an
    inference thread; health, the alert state and the outputs belong to the caller's thread. The send cycle
    alone decides the status (the hazard is published to it); the overlay and the maps are drawn and encoded
    on threads of their own, at most ``SINK_BEHIND`` frames behind, each a :class:`GuardedSink`.
    """

    SINK_BEHIND = 4     # frames an overlay or maps output may fall behind the loop
    LOG_BEHIND = 64     # lines the frame log may fall behind

    def __init__(self, engine: Engine, source: Source, senders: list[Sender], cfg: RuntimeConfig,
                 camera: CameraState, outputs: Outputs, clock: Callable[[], float]) -> None:
        self.engine, self.source, self.senders, self.cfg, self.camera = engine, source, senders, cfg, camera
        self.outputs = outputs
        self.geometry = SectorGeometry(engine.card.camera, cfg.sectors)
        self.names = cfg.sectors.names
        self.machines = [SectorState(cfg.alerts) for _ in self.names]
        self.health = Health(cfg.health)
        self.visibility = CameraHealth(cfg.visibility, self.geometry.column_sector, len(self.names))
        self.blind = BlindnessLog()
        self.wall = None if source.live else clock    # a live source's frame times are the processing clock
        if not engine.authentic:        # said on every cycle: nobody trusted vouches for this model
            self.health.set_fault(Fault.UNSIGNED_MODEL, 1)
        self.emitter = CycleEmitter(senders, self.health, cfg.cycle_s, self.wall, cfg.messages, cfg.bus.down_after_s)
        self.timer = StageTimer()
        self.latency = LatencyStats()
        self.cpu = CpuMeter()
        self.waiting = LatencyStats()        # warped frames waiting for the model (overlap)
        self.sinks: dict[str, GuardedSink] = {}
        self.heartbeat: Heartbeat | None = None
        self.feeder: Feeder | None = None
        self.pool: ThreadPoolExecutor | None = None     # the inference threads, with frames in flight
        self.frames = self.valid = 0
        self.shape: tuple[int, ...] | None = None      # the source's frames' shape: its first frame's
        self.reconnects_seen = 0
        self._camera_file_failed = False
        self.last_t = 0.0
        self.stages: tuple[Stage, ...] = tuple(kind(self) for kind in WAY)

    def stage(self, name: str) -> Stage:
        """The stage of the way called ``name`` (one of :data:`STAGES`)."""
        return next(st for st in self.stages if st.name == name)

    @property
    def dropped(self) -> int:
        """Frames the model had no time for: skipped by a live source, or replaced in the feeder's slot."""
        return self.source.dropped + (self.feeder.dropped if self.feeder is not None else 0)

    def warp(self, cap: Captured, buf: np.ndarray) -> tuple[ModelFrame, bool] | None:
        """The frame shown to online calibration, then into the model camera, written into the input
        buffer ``buf``; whether the camera was still calibrating for it. None, with nothing done, for a
        file's frame of another size than its source's (:meth:`read` counts it): neither calibration nor
        a model frame is built for a size the source does not have (a 25-megapixel picture in a folder of
        1280x720 frames took 580 MB for maps it would never use)."""
        frame = cap.frame
        if frame is None:
            raise ValueError(f"frame {cap.index} did not decode: nothing to warp")
        size = self.source.size
        if not self.source.live and not self.source.reconnects and self.source.one_camera and size is not None \
                and frame.shape[:2] != (size[1], size[0]):
            return None
        self.camera.picture(cap.picture, frame)
        self.camera.observe(frame)
        if self.camera.save_failure is not None and not self._camera_file_failed:
            self._camera_file_failed = True            # the saved camera file is an output like the others
            self.health.fault(Fault.SINK_ERRORS)
        mf = self.camera.frame_for(frame)
        mf.to_model(frame, dst=buf[0])
        return mf, self.camera.calibrating

    def infer(self, buf: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        """The model on ``buf``: (prob, depth, when it began, seconds). The one inference path, on the
        loop's thread or (``in_flight`` > 1) on an inference thread (:meth:`start`)."""
        t0 = time.perf_counter()
        prob, depth = self.engine.infer(buf)
        return prob, depth, t0, time.perf_counter() - t0

    def start(self, item: Prepared) -> Future | None:
        """The frame's inference started on one of the loop's inference threads (``in_flight`` > 1);
        None when there is nothing to run there (the loop's thread then runs it in :meth:`step`)."""
        if item.cap.frame is None or item.buf is None or self.pool is None:
            return None
        return self.pool.submit(self.infer, item.buf)

    # -- the run ---------------------------------------------------------------------------------

    def open(self) -> None:
        """Start the heartbeat (live) and open the outputs, each on its own thread; one that refuses to
        open raises (the run is refused: the user asked for it); one still opening after ``OPEN_WAIT_S``
        is not waited for (stuck, it fails later), and later failures only degrade the run."""
        self.camera.use_frame_rate(self.source.fps, live=self.source.live)
        # a camera's cycles go out on the wall clock; a file's by its frames' times, watched on the wall clock
        self.heartbeat = (Heartbeat(self.emitter) if self.source.live
                          else StallWatch(self.emitter, self.cfg.health.deadline_s)).start()
        out = self.outputs

        def fault(_: SinkFailure) -> None:
            self.health.fault(Fault.SINK_ERRORS)

        # drawing and encoding the overlay, and encoding the maps, on threads of their own
        behind: dict[str, Any] = {"behind": self.SINK_BEHIND, "drop_when_full": self.source.live}
        if out.overlay is not None:
            writer = OverlayWriter(out.overlay, self.source.fps)

            def overlay(frame: np.ndarray, mf: ModelFrame, mask: np.ndarray, alert: AlertFrame) -> None:
                writer.write(draw(frame, mf, mask, alert, self.geometry))

            self.sinks["overlay"] = GuardedSink("overlay", overlay, writer.close, fault, open=writer.open, **behind)
        if out.log is not None:
            # a line at a time: readable while it runs, and every line whole after a kill
            log = LineLog(out.log)
            self.sinks["log"] = GuardedSink("log", log.write, log.close, fault, behind=self.LOG_BEHIND,
                                            drop_when_full=self.source.live, open=log.open)
        if out.maps is not None:
            maps = out.maps

            def write_maps(name: str, mf: ModelFrame, prob: np.ndarray, depth: np.ndarray) -> None:
                maps.write(name, mf.to_raw(prob), mf.depth_to_raw(depth))

            self.sinks["maps"] = GuardedSink("maps", write_maps, None, fault, **behind)
        open_all(self.sinks.values())

    def step(self, item: Prepared, inflight: Future | None = None) -> None:
        """One prepared frame along the way; ``inflight``: its inference, already started on another thread
        (:meth:`start`), whose answer the inference stage waits for."""
        cap = item.cap
        t0 = time.perf_counter()
        for sink in self.sinks.values():     # an output stuck for a second is a fault now, whatever the frame
            sink.check()
        w = Work(item, FrameRecord(cap.index, cap.t, names=self.names), inflight)
        self.through(w)
        t0 = min(t0, w.began)          # the frame's path began with its inference at the latest
        # a camera's frame: from its capture (the read returned) to its alert, waiting included; a
        # file's: its own path, decode to alert (the time it waited for the model is counted apart)
        latency = time.monotonic() - cap.t if self.source.live else w.sent_at - t0 + item.warp_s + cap.decode_s
        self.latency.add(latency)
        self.waiting.add(max(0.0, t0 - item.ready_at))
        log = self.sinks.get("log")
        if log is not None:
            w.rec.latency_ms = 1e3 * latency
            log.write(cap.index, w.rec.to_json())

    def through(self, w: Work) -> None:
        """``w`` along the way, each stage timed into the run's totals and the frame's ``stage_ms`` (at the
        seconds its work took on another thread, when it ran there); after a stage that ends the frame's way
        only those that run for every frame (the send cycle)."""
        go = True
        for stage in self.stages:
            if not (go or stage.always):
                continue
            t0 = time.perf_counter()
            go = stage.run(w) and go
            away = stage.elsewhere(w)
            seconds = time.perf_counter() - t0 if away is None else away
            self.timer.add(stage.name, seconds)
            w.rec.stage_ms[stage.name] = 1e3 * seconds

    def close(self) -> None:
        """Whatever ended the run (the source, a signal, an exception): the outputs are finished, then
        the last word on every bus is UNAVAILABLE, since no valid inference is coming any more."""
        if self.feeder is not None:
            self.feeder.close()
        h = self.health
        h.set_fault(Fault.SOURCE_RECONNECTS, self.source.reconnects)
        if self.source.unread:
            h.fault(Fault.DECODE_ERRORS, self.source.unread)
        h.unavailable()         # the heartbeat says so while the outputs finish
        for sink in self.sinks.values():
            sink.close(self.frames)
        self.camera.close()
        if self.heartbeat is not None:
            self.heartbeat.close()
        self.emitter.final(time.monotonic() if self.source.live else self.last_t + self.cfg.cycle_s)

    def run(self, max_frames: int | None = None, progress: Callable[[int], Any] | None = None,
            stop: threading.Event | None = None) -> dict[str, Any]:
        """Process the source until it ends, ``max_frames`` or ``stop``; returns the summary as written
        (:meth:`RunSummary.to_json <bsn_edge.runtime.run_summary.RunSummary.to_json>`).

        With ``in_flight`` > 1 the model runs that many frames at once, each on an inference thread of
        its own (an engine of one intra-op thread each: two on two cores do more frames a second than
        one inference split over both, each frame's answer later); everything after the inference
        happens on this thread, in the frames' order, as with one in flight."""
        self.engine.warmup(self.cfg.warmup)
        t_start = time.perf_counter()
        overlap, held = self.cfg.overlap, self.cfg.in_flight
        extra = Feeder.buffers_needed(held) - 1 if overlap else 0
        buffers = [self.engine.buf] + [np.empty_like(self.engine.buf) for _ in range(extra)]
        pending: deque[tuple[Prepared, Future | None]] = deque()
        try:
            self.open()
            self.feeder = Feeder(self.source, self.warp, buffers, background=overlap, limit=max_frames,
                                 nice=self.cfg.feeder_nice, held=held)
            if held > 1:
                self.pool = ThreadPoolExecutor(held, thread_name_prefix="bsn-infer")
            def done() -> bool:
                return (max_frames is not None and self.frames >= max_frames) or (stop is not None and stop.is_set())

            def drain(keep: int) -> bool:
                """Step the oldest frames until ``keep`` are left in flight; whether the run is done."""
                while len(pending) > keep and not done():
                    self.step(*pending.popleft())
                    self.cpu.frame(self.frames)
                    if progress:
                        progress(1)
                return done()

            for item in self.feeder:
                pending.append((item, self.start(item)))
                if drain(held - 1):
                    break
            else:
                drain(0)                  # the source ended with frames still in the model
        finally:
            if self.pool is not None:
                self.pool.shutdown(wait=True, cancel_futures=True)
            self.close()
        return self.summary(time.perf_counter() - t_start, stop).to_json()

    def summary(self, elapsed: float, stop: threading.Event | None) -> RunSummary:
        card, frames, maps = self.engine.card, self.frames, self.outputs.maps
        return RunSummary(
            frames=frames, valid_frames=self.valid, dropped=self.dropped, before_start=self.source.before_start,
            overlap=self.cfg.overlap, in_flight=self.cfg.in_flight, seconds=round(elapsed, 3),
            fps=frames / elapsed if elapsed else 0.0, latency_ms=self.latency.percentiles(),
            wait_ms={k.removesuffix("_ms"): v for k, v in self.waiting.percentiles().items()},
            stage_ms=self.timer.per_frame_ms(frames), stage_share=self.timer.shares(), faults=self.health.faults,
            cycles_sent=self.emitter.sent_cycles, stall_cycles=self.emitter.stall_cycles,
            states_s={k: round(n * self.cfg.cycle_s, 2) for k, n in self.emitter.state_cycles.items()},
            why_s={k: {why: round(n * self.cfg.cycle_s, 2) for why, n in v.items()}
                   for k, v in self.emitter.why_cycles.items()},
            senders={s.name: vars(s.stats) for s in self.senders},
            senders_down=self.health.senders_down, source_failure=self.source.failure,
            stopped=bool(stop is not None and stop.is_set()),
            heartbeat_error=self.heartbeat.last_error if self.heartbeat is not None else "",
            camera=self.camera.summary(), visibility=self.blind.to_json(), cpu=self.cpu.figures(),
            maps_written=0 if maps is None else maps.written,
            sinks={**{name: SinkSummary(k.written, k.dropped, None if k.ok else vars(k.failure))
                      for name, k in self.sinks.items()},
                   **({} if self.camera.save_failure is None
                      else {CAMERA_FILE: SinkSummary(0, 0, vars(self.camera.save_failure))})},
            model=ModelSummary(card.variant, card.input_size, self.engine.threshold, card.quantization,
                               self.engine.kernels, self.engine.self_test, self.engine.signer,
                               self.engine.authentic, self.engine.verdict.note, card.graph_sha256 or "",
                               card.config_digest or ""))


def run(engine: Engine, source: Source, senders: list[Sender], cfg: RuntimeConfig | None = None,
        overlay: str | Path | None = None, log: str | Path | None = None, max_frames: int | None = None,
        progress=None, camera: CameraState | None = None, save_maps: str | Path | MapWriter | None = None,
        stop: threading.Event | None = None, clock: Callable[[], float] = time.monotonic) -> dict[str, Any]:
    """Process ``source`` until it ends, ``max_frames`` or ``stop`` is set; returns the summary.

    Every frame is warped into the model camera by ``camera`` (a :class:`CameraState`: the
    user's camera file, or online calibration, see there); the sectors are bearings in the model
    camera, which looks along the car, and distances are brought to the user's camera height.
    The overlay and ``save_maps`` (per frame ``<name>_blindspot.png``, 8-bit probability, and
    ``<name>_depth.png``, 16-bit metres x 256, 0 = none; a folder or a :class:`MapWriter`) are in
    the raw frame's own pixels.
    Whatever ends the run, the last cycle on every bus says UNAVAILABLE, and the summary's
    ``source_failure`` says whether the source failed. The frame rate on the bus and the overlay
    is the one achieved, counted on ``clock`` (a file's frame times say how fast it was recorded).
    """
    maps = save_maps if isinstance(save_maps, MapWriter) or save_maps is None else MapWriter(save_maps)
    pipeline = FramePipeline(engine, source, senders, cfg or RuntimeConfig(), camera or CameraState(engine.card),
                             Outputs(overlay, log, maps), clock)
    return pipeline.run(max_frames, progress, stop)
