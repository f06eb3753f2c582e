"""The edge loop: frame -> fused model -> sectors -> smoothing -> alert state -> senders.

Never falls over: an undecodable frame, a frame of another size, NaN in the output or a
failing sender is counted (status message and log), and the loop goes on.
"""

from __future__ import annotations

import json
import time
from contextlib import ExitStack
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
from bsn_edge.alerts.health import Health
from bsn_edge.alerts.senders import Sender
from bsn_edge.calibration.chessboard import Calibration
from bsn_edge.runtime.cycle import CycleEmitter, Heartbeat
from bsn_edge.runtime.engine import Engine
from bsn_edge.runtime.overlay import OverlayWriter, draw
from bsn_edge.runtime.sources import Source

STAGES = ("decode", "preprocess", "inference", "postprocess", "send")


@dataclass(frozen=True)
class RuntimeConfig:
    alerts: AlertConfig = field(default_factory=AlertConfig)
    sectors: SectorConfig = field(default_factory=SectorConfig)
    health: HealthConfig = field(default_factory=HealthConfig)
    cycle_s: float = 0.1
    warmup: int = 3


def _percentiles(xs: list[float]) -> dict[str, float]:
    if not xs:
        return {"p50_ms": 0.0, "p95_ms": 0.0, "p99_ms": 0.0}
    a = np.array(xs) * 1e3
    return {"p50_ms": float(np.percentile(a, 50)), "p95_ms": float(np.percentile(a, 95)),
            "p99_ms": float(np.percentile(a, 99))}


def run(engine: Engine, source: Source, senders: list[Sender], cfg: RuntimeConfig | None = None,
        overlay: str | Path | None = None, log: str | Path | None = None, max_frames: int | None = None,
        progress=None, calibration: Calibration | None = None) -> dict[str, Any]:
    """Process ``source`` until it ends (or ``max_frames``); returns the summary.

    ``calibration`` (from bsn-calibrate) replaces the model's intrinsics for the sector bearings,
    and frames are undistorted first when it carries distortion.
    """
    cfg = cfg or RuntimeConfig()
    intr = calibration.intrinsics if calibration is not None else engine.info.intrinsics
    undistorters: dict[tuple[int, int], Any] = {}
    h, w = engine.info.size
    if intr is None:
        from bsn_edge.camera import Intrinsics
        intr = Intrinsics.from_fov(w, h, 80.0)
    geometry = SectorGeometry(intr.scaled(w, h) if (intr.width, intr.height) != (w, h) else intr, cfg.sectors)
    machines = [SectorState(cfg.alerts) for _ in range(3)]
    health = Health(cfg.health)
    emitter = CycleEmitter(senders, health, cfg.cycle_s)
    engine.warmup(cfg.warmup)
    stage_s = dict.fromkeys(STAGES, 0.0)
    latencies: list[float] = []
    frames = valid = 0
    last_shape = None
    t_start = time.perf_counter()
    with ExitStack() as stack:
        if source.live:
            stack.enter_context(Heartbeat(emitter))
        writer = None
        if overlay is not None:
            fps = getattr(source, "fps", 10.0)
            writer = OverlayWriter(overlay, (h, w), fps)
            stack.callback(writer.close)
        logf = None
        if log is not None:
            Path(log).parent.mkdir(parents=True, exist_ok=True)
            logf = stack.enter_context(open(log, "w"))
        for cap in source:
            t0 = time.perf_counter()
            frames += 1
            health.faults["dropped_frames"] = source.dropped  # live sources drop while we work
            stage_s["decode"] += cap.decode_s
            rec: dict[str, Any] = {"frame": cap.index, "t": round(cap.t, 4)}
            if cap.frame is None:
                health.fault("decode_errors")
                rec["fault"] = "decode_error"
            else:
                if last_shape is not None and cap.frame.shape != last_shape:
                    health.fault("size_changes")
                    rec["fault"] = "size_change"
                last_shape = cap.frame.shape
                img = cap.frame
                if calibration is not None and calibration.has_distortion:
                    fh, fw = img.shape[:2]
                    if (fw, fh) not in undistorters:
                        undistorters[(fw, fh)] = calibration.undistorter(fw, fh)
                    img = undistorters[(fw, fh)](img)
                batch = engine.preprocess(img)
                t1 = time.perf_counter()
                prob, depth = engine.infer(batch)
                t2 = time.perf_counter()
                stage_s["preprocess"] += t1 - t0
                stage_s["inference"] += t2 - t1
                if not (np.isfinite(prob).all() and np.isfinite(depth).all()):
                    health.fault("nan_outputs")
                    rec["fault"] = "nan_output"
                else:
                    mask = prob >= engine.info.threshold
                    readings = geometry.read(mask, depth)
                    sectors = []
                    for m, r in zip(machines, readings, strict=True):
                        score, level = m.update(cap.t, r.score)
                        sectors.append(SectorAlert(score, level, r.distance_m))
                    health.valid(cap.t)
                    valid += 1
                    alert = AlertFrame(cap.t, *sectors, health.state(cap.t), health.fps(cap.t), dict(health.faults))
                    emitter.publish(alert)
                    t3 = time.perf_counter()
                    stage_s["postprocess"] += t3 - t2
                    rec.update(levels=[s.level.name for s in sectors], scores=[round(s.score, 3) for s in sectors],
                               distances=[None if s.distance_m is None else round(s.distance_m, 2) for s in sectors],
                               state=alert.state.name)
                    if writer is not None:
                        writer.write(draw(batch[0], mask, alert, geometry))
            t4 = time.perf_counter()
            if not source.live:
                emitter.emit(cap.t)
            t5 = time.perf_counter()
            stage_s["send"] += t5 - t4
            latencies.append(t5 - t0 + cap.decode_s)
            if logf is not None:
                rec["latency_ms"] = round(1e3 * (t5 - t0 + cap.decode_s), 2)
                logf.write(json.dumps(rec) + "\n")
            if progress:
                progress(1)
            if max_frames is not None and frames >= max_frames:
                break
    wall = time.perf_counter() - t_start
    total = sum(stage_s.values()) or 1.0
    sender_stats = {s.name: vars(s.stats) for s in senders}
    return {"frames": frames, "valid_frames": valid, "dropped": source.dropped, "seconds": round(wall, 3),
            "fps": frames / wall if wall else 0.0, **_percentiles(latencies),
            "stage_ms": {k: 1e3 * v / max(frames, 1) for k, v in stage_s.items()},
            "stage_share": {k: v / total for k, v in stage_s.items()},
            "faults": dict(health.faults), "cycles_sent": emitter.sent_cycles, "senders": sender_stats,
            "model": {"variant": engine.info.variant, "size": list(engine.info.size),
                      "threshold": engine.info.threshold, "quantization": engine.info.quantization}}
