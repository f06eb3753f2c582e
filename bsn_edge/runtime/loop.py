"""The edge loop: frame -> fused model -> sectors -> smoothing -> alert state -> senders.

Never falls over: an undecodable frame, a frame of another size, NaN in the output or a
failing sender is counted (status message and log), and the loop goes on. Never looks healthy
when it is not: whatever ends the run, the last status on every bus is UNAVAILABLE.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.alerts import (
    AlertConfig,
    AlertFrame,
    HealthConfig,
    SectorAlert,
    SectorConfig,
    SectorGeometry,
    SectorState,
)
from bsn_edge.alerts.health import Fault, Health
from bsn_edge.alerts.senders import Sender
from bsn_edge.model_frame import ModelFrame
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.cycle import CycleEmitter, Heartbeat
from bsn_edge.runtime.engine import Engine
from bsn_edge.runtime.maps import MapWriter
from bsn_edge.runtime.overlay import OverlayWriter, draw
from bsn_edge.runtime.sinks import GuardedSink, SinkFailure
from bsn_edge.runtime.sources import Source
from bsn_edge.runtime.stats import LatencyStats
from bsn_edge.sequence.folder import frame_name

STAGES = ("decode", "preprocess", "inference", "postprocess", "send")


def blind_spots(prob: np.ndarray, threshold: float, mf: ModelFrame) -> np.ndarray:
    """The blind-spot mask the sectors read: above threshold and where the camera sees. Where a
    camera narrower than the model camera sees nothing, the model's input is the frame mirrored
    from its edge; a blind spot found in a mirrored car is not in the world."""
    return (prob >= threshold) & mf.seen


@dataclass(frozen=True)
class RuntimeConfig:
    alerts: AlertConfig = field(default_factory=AlertConfig)
    sectors: SectorConfig = field(default_factory=SectorConfig)
    health: HealthConfig = field(default_factory=HealthConfig)
    cycle_s: float = 0.1
    warmup: int = 3


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
    cfg = cfg or RuntimeConfig()
    camera = camera or CameraState(engine.card)
    geometry = SectorGeometry(engine.card.camera, cfg.sectors)
    maps = save_maps if isinstance(save_maps, MapWriter) or save_maps is None else MapWriter(save_maps)
    machines = [SectorState(cfg.alerts) for _ in range(3)]
    health = Health(cfg.health)
    wall = None if source.live else clock        # a live source's frame times are the processing clock
    emitter = CycleEmitter(senders, health, cfg.cycle_s, wall)
    engine.warmup(cfg.warmup)
    stage_s = dict.fromkeys(STAGES, 0.0)
    latency = LatencyStats()
    frames = valid = 0
    last_shape = None
    last_t = 0.0
    t_start = time.perf_counter()

    def sink_fault(_: SinkFailure) -> None:
        health.fault(Fault.SINK_ERRORS)

    sinks: dict[str, GuardedSink] = {}
    heartbeat = None
    try:
        camera.use_frame_rate(source.fps)
        if source.live:
            heartbeat = Heartbeat(emitter).__enter__()
        # outputs that cannot be opened refuse the run (the user asked for them); later failures degrade it
        if overlay is not None:
            writer = OverlayWriter(overlay, source.fps)
            sinks["overlay"] = GuardedSink("overlay", writer.write, writer.close, sink_fault)
        if log is not None:
            Path(log).parent.mkdir(parents=True, exist_ok=True)
            # line-buffered: readable while it runs, and every line whole after a kill
            logf = open(log, "w", buffering=1)  # noqa: SIM115 - closed by its sink
            sinks["log"] = GuardedSink("log", lambda rec: logf.write(json.dumps(rec) + "\n"), logf.close, sink_fault)
        if maps is not None:
            sinks["maps"] = GuardedSink("maps", maps.write, None, sink_fault)
        overlay_sink, log_sink, maps_sink = sinks.get("overlay"), sinks.get("log"), sinks.get("maps")
        for cap in source:
            t0 = time.perf_counter()
            frames += 1
            last_t = cap.t
            health.set_fault(Fault.DROPPED_FRAMES, source.dropped)  # live sources drop while we work
            health.set_fault(Fault.SOURCE_RECONNECTS, source.reconnects)
            stage_s["decode"] += cap.decode_s
            rec: dict[str, Any] = {"frame": cap.index, "t": round(cap.t, 4)}
            if cap.frame is None:
                health.fault(Fault.DECODE_ERRORS)
                rec["fault"] = "decode_error"
            else:
                if last_shape is not None and cap.frame.shape != last_shape:
                    health.fault(Fault.SIZE_CHANGES)
                    rec["fault"] = "size_change"
                last_shape = cap.frame.shape
                mf = camera.frame_for(cap.frame)
                health.calibrating(camera.calibrating)
                batch = engine.buf
                mf.to_model(cap.frame, dst=batch[0])
                t1 = time.perf_counter()
                prob, depth = engine.infer(batch)
                t2 = time.perf_counter()
                stage_s["preprocess"] += t1 - t0
                stage_s["inference"] += t2 - t1
                if not (np.isfinite(prob).all() and np.isfinite(depth).all()):
                    health.fault(Fault.NAN_OUTPUTS)
                    rec["fault"] = "nan_output"
                else:
                    mask = blind_spots(prob, engine.card.threshold, mf)
                    readings = geometry.read(mask, mf.depth_to_metres(depth))
                    sectors = []
                    for m, r in zip(machines, readings, strict=True):
                        score, level = m.update(cap.t, r.score)
                        sectors.append(SectorAlert(score, level, r.distance_m))
                    now = None if wall is None else wall()
                    health.valid(cap.t, now)
                    valid += 1
                    state, fps_now, faults = health.snapshot(cap.t, now)
                    alert = AlertFrame(cap.t, *sectors, state, fps_now, faults)
                    emitter.publish(alert)
                    t3 = time.perf_counter()
                    stage_s["postprocess"] += t3 - t2
                    rec.update(levels=[s.level.name for s in sectors], scores=[round(s.score, 3) for s in sectors],
                               distances=[None if s.distance_m is None else round(s.distance_m, 2) for s in sectors],
                               state=alert.state.name)
                    if overlay_sink is not None and overlay_sink.ok:
                        overlay_sink.write(cap.index, draw(cap.frame, mf, mask, alert, geometry))
                    if maps_sink is not None and maps_sink.ok:
                        maps_sink.write(cap.index, cap.name or frame_name(cap.index, ""), mf.to_raw(prob),
                                        mf.depth_to_raw(depth))
            t4 = time.perf_counter()
            if not source.live:
                emitter.emit(cap.t)
            t5 = time.perf_counter()
            stage_s["send"] += t5 - t4
            latency.add(t5 - t0 + cap.decode_s)
            if log_sink is not None:
                rec["latency_ms"] = round(1e3 * (t5 - t0 + cap.decode_s), 2)
                log_sink.write(cap.index, rec)
            if progress:
                progress(1)
            if (max_frames is not None and frames >= max_frames) or (stop is not None and stop.is_set()):
                break
    finally:
        # whatever ended the run (the source, a signal, an exception): outputs are finished, then the
        # last word on every bus is UNAVAILABLE, since no valid inference is coming any more
        for sink in sinks.values():
            sink.close(frames)
        camera.close()
        health.set_fault(Fault.SOURCE_RECONNECTS, source.reconnects)
        if source.unread:
            health.fault(Fault.DECODE_ERRORS, source.unread)
        health.unavailable()
        if heartbeat is not None:
            heartbeat.close()
        emitter.final(time.monotonic() if source.live else last_t + cfg.cycle_s)
    elapsed = time.perf_counter() - t_start
    total = sum(stage_s.values()) or 1.0
    sender_stats = {s.name: vars(s.stats) for s in senders}
    card = engine.card
    return {"frames": frames, "valid_frames": valid, "dropped": source.dropped, "seconds": round(elapsed, 3),
            "fps": frames / elapsed if elapsed else 0.0, **latency.percentiles(),
            "stage_ms": {k: 1e3 * v / max(frames, 1) for k, v in stage_s.items()},
            "stage_share": {k: v / total for k, v in stage_s.items()},
            "faults": health.faults, "cycles_sent": emitter.sent_cycles, "senders": sender_stats,
            "source_failure": source.failure, "stopped": bool(stop is not None and stop.is_set()),
            "heartbeat_error": heartbeat.last_error if heartbeat is not None else "",
            "camera": camera.summary(), "maps_written": 0 if maps is None else maps.written,
            "sinks": {name: {"written": k.written, "failure": None if k.ok else vars(k.failure)}
                      for name, k in sinks.items()},
            "model": {"variant": card.variant, "size": list(card.input_size), "threshold": card.threshold,
                      "quantization": card.quantization, "self_test": engine.self_test, "signer": engine.signer}}
