"""Where a frame's CPU goes in ``bsn-run``, each part timed on its own (reading, decoding, the model), and the
ceiling they leave end to end on 2 cores: ``bench_runtime``'s budget rows."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.calibration import Calibration
from bsn_edge.runtime import Engine, open_source
from bsn_edge.runtime.camera_state import CameraState

SHARE_BAR = 0.9       # end to end against the model's own frames/s


def per_call_ms(fn: Callable[[int], object], n: int, warmup: int = 5) -> tuple[float, float]:
    """Wall and CPU milliseconds per call of ``fn(i)``, ``i`` from 0 to ``n`` - 1 after ``warmup`` calls
    of ``fn(0)``; CPU: user + system of every thread of this process (the model's pool, FFmpeg's,
    online calibration's)."""
    for _ in range(warmup):
        fn(0)
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(n):
        fn(i)
    return 1e3 * (time.perf_counter() - w0) / n, 1e3 * (time.process_time() - c0) / n


def ceiling(model_wall_ms: float, model_cpu_ms: float, reading_cpu_ms: float, cores: int = 2) -> dict[str, float]:
    """The most frames/s end to end can reach on ``cores`` when reading a frame (decode, warp, online
    calibration) costs ``reading_cpu_ms`` of CPU and the model ``model_cpu_ms`` of CPU in
    ``model_wall_ms``: the cores must do both for every frame, and no frame is faster than the model
    alone. ``share``: that ceiling over the model's own frames/s."""
    if min(model_wall_ms, model_cpu_ms) <= 0 or reading_cpu_ms < 0 or cores < 1:
        raise ValueError(f"times must be positive and cores >= 1, got {model_wall_ms}, {model_cpu_ms}, "
                         f"{reading_cpu_ms}, {cores}")
    model_fps = 1e3 / model_wall_ms
    fps = min(model_fps, cores * 1e3 / (model_cpu_ms + reading_cpu_ms))
    return {"fps": fps, "share": fps / model_fps}


def cpu_budget(model: str, video: Path, frames: int, calibration: Calibration | None) -> dict[str, float]:
    """Where a frame's CPU goes, each part timed on its own: reading (decode, warp into the model camera
    and, without a camera file, online calibration, as ``bsn-run``'s feeder does them), decoding alone,
    and the model (2 threads, idle threads sleeping, as ``bsn-run`` runs it); and the ceiling they leave
    end to end."""
    engine = Engine(model, threads=2, spinning=False)
    source = open_source(str(video))
    frames_in = iter(source)
    try:
        _, decode_cpu = per_call_ms(lambda _: next(frames_in), frames)
    finally:
        source.stop()
    camera = CameraState(engine.card, calibration)
    source = open_source(str(video))
    camera.use_frame_rate(source.fps)
    buf = np.empty((1, *engine.card.input_size, 3), np.uint8)
    caps = iter(source)
    batches: list[np.ndarray] = []

    def read(_: int) -> None:
        frame = next(caps).frame
        if frame is not None:
            camera.observe(frame)
            camera.frame_for(frame).to_model(frame, dst=buf[0])
            if len(batches) < frames:
                batches.append(buf.copy())

    try:
        read_wall, read_cpu = per_call_ms(read, frames)
    finally:
        camera.close()
        source.stop()
    if not batches:
        raise ValueError(f"{video}: no frame of it decoded")
    model_wall, model_cpu = per_call_ms(lambda i: engine.infer(batches[i % len(batches)]), len(batches))
    c = ceiling(model_wall, model_cpu, read_cpu)
    return {"read_wall_ms": read_wall, "read_cpu_ms": read_cpu, "decode_cpu_ms": decode_cpu,
            "model_wall_ms": model_wall, "model_cpu_ms": model_cpu, "ceiling_fps": c["fps"],
            "ceiling_share": c["share"]}


BUDGET_KEYS = ("read_wall_ms", "read_cpu_ms", "decode_cpu_ms", "model_wall_ms", "model_cpu_ms", "ceiling_fps",
               "ceiling_share")


def budget_table(rows: list[dict[str, Any]]) -> list[str]:
    """Markdown: :func:`cpu_budget`'s figures, each (clip, model, camera)'s median over its runs."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["clip"], r["model_file"], r["camera_file"]), []).append(r)
    out = ["## Where a frame's CPU goes, and the ceiling it leaves end to end", "",
           "Each part timed on its own: reading (decode, warp into the model camera, and online calibration "
           "without a camera file, as `bsn-run`'s feeder does them), decoding alone, and the model (2 threads, "
           "idle threads sleeping); CPU: user + system of every thread. The 2 cores must do both for every "
           "frame, so end to end cannot pass 2 / (model CPU + reading CPU), nor the model's own rate: that "
           f"ceiling, against the {100 * SHARE_BAR:.0f} % bar. Medians over the runs (their number in brackets).", "",
           "| clip | model | camera | reading ms (CPU ms) | of which decode, CPU ms | model ms (CPU ms) | "
           "ceiling frames/s | ceiling, % of model only |", "|---|---|---|---|---|---|---|---|"]
    for (clip, model, cam), rs in groups.items():
        m = {k: statistics.median(r[k] for r in rs) for k in BUDGET_KEYS}
        out.append(f"| {clip} | {model} | {'file' if cam else 'calibrating'} | {m['read_wall_ms']:.1f} "
                   f"({m['read_cpu_ms']:.1f}) | {m['decode_cpu_ms']:.1f} | {m['model_wall_ms']:.1f} "
                   f"({m['model_cpu_ms']:.1f}) | "
                   f"{m['ceiling_fps']:.1f} ({len(rs)}) | {100 * m['ceiling_share']:.0f} % |")
    return out


