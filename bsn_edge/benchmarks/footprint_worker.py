"""One row of ``bench_footprint``, in a process of its own: the runtime as ``bsn-run`` runs it on a real clip
paced at a camera's rate, and the int8 model alone after it; prints the figures as one JSON line.

    PYTHONPATH=TREE python bsn_edge/benchmarks/footprint_worker.py CLIP RATE [--calib CAMERA.json] [--loops N]

A script, not a module of the benchmarks: it imports only ``bsn_edge``, from the tree ``PYTHONPATH`` names
(the code before a change is measured with the same worker as the code after it).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

WARM = 20                  # frames before the CPU is counted: the model's first runs and the first cycles
MODEL_FRAMES = 150


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _looped(clip: Path, rate: float, loops: int) -> Any:
    """``clip`` played ``loops`` times over on one clock at ``rate`` frames a second, paced (a source of the tree
    on the path: imported here)."""
    from bsn_edge.runtime.sources import Captured, Source, VideoFileSource

    class Looped(Source):
        def __init__(self) -> None:
            super().__init__()
            first = VideoFileSource(clip)
            # paced here, not by the base class: the code before a change may not pace a source of its own
            self.size, self.total, self.fps = first.size, (first.total or 0) * loops, rate
            first.close()
            self._open: VideoFileSource | None = None

        def _frames(self) -> Iterator[Captured]:
            k, start = 0, time.monotonic()
            for _ in range(loops):
                self._open = VideoFileSource(clip)
                for c in self._open:
                    wait = start + k / rate - time.monotonic()
                    if wait > 0:
                        time.sleep(wait)
                    yield Captured(k / rate, c.frame, k, c.decode_s)
                    k += 1
                self._open.close()

        def _release(self) -> None:
            if self._open is not None:
                self._open.close()

    return Looped()


def _frame_log(path: Path, loops: int, per_loop: int) -> tuple[list[float], dict[str, list[float]]]:
    """Each frame's latency and stage times from the run's frame log, after the first ``WARM`` frames."""
    stage_ms: dict[str, list[float]] = {}
    lat = []
    for line in path.read_text().splitlines()[WARM:]:
        rec = json.loads(line)
        if loops > 1 and rec["frame"] % per_loop == 0:
            continue            # the first frame of a replay waits for the file's reopening: no camera does
        lat.append(rec["latency_ms"])
        for k, v in rec["stage_ms"].items():
            stage_ms.setdefault(k, []).append(v)
    return lat, stage_ms


def _model_alone(engine: Any, rate: float) -> float:
    """The model alone on the last frame the loop warped, paced the same, in this process: CPU ms a frame."""
    engine.infer(engine.buf)
    m0, t = _cpu(), time.perf_counter()
    for i in range(MODEL_FRAMES):
        engine.infer(engine.buf)
        wait = t + (i + 1) / rate - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    return 1e3 * (_cpu() - m0) / MODEL_FRAMES


def worker(clip: Path, rate: float, calib: str | None, loops: int, settings: dict[str, Any] | None = None
           ) -> dict[str, Any]:
    """One row, in this process: the runtime on ``clip`` paced at ``rate``; the figures as a dict."""
    try:
        from bsn_edge.alerts.can_output import CanSender
    except ImportError:             # a tree from before each output had its module
        from bsn_edge.alerts.senders import CanSender  # type: ignore[attr-defined,no-redef]
    from bsn_edge.calibration import Calibration
    from bsn_edge.default_model import DEFAULT_MODEL
    from bsn_edge.modelfile.trust import TrustPolicy
    from bsn_edge.runtime import Engine
    from bsn_edge.runtime import run as run_loop
    from bsn_edge.runtime.camera_state import CameraState
    from bsn_edge.runtime.settings import RuntimeConfig

    cfg = RuntimeConfig(**(settings or {}))       # [runtime] settings to compare (a profile's A/B)
    engine = Engine(DEFAULT_MODEL, cfg.engine_threads, cfg.spin, trust=TrustPolicy.default([], False))
    camera = CameraState(engine.card, Calibration.read(calib) if calib else None)
    source = _looped(clip, rate, loops)
    tmp = Path(tempfile.mkdtemp())
    marks: dict[int, tuple[float, float]] = {}
    frames = [0]

    def progress(n: int) -> None:
        frames[0] += n
        marks[frames[0]] = (time.perf_counter(), _cpu())

    with CanSender("virtual", f"bsn-footprint-{os.getpid()}", log_path=str(tmp / "bus.log")) as tx:
        summary = run_loop(engine, source, [tx], cfg, log=tmp / "frames.jsonl", progress=progress, camera=camera)
    last = max(marks)
    (w0, c0), (w1, c1) = marks[WARM], marks[last]
    lat, stage_ms = _frame_log(tmp / "frames.jsonl", loops, source.total // loops)
    model_cpu_ms = _model_alone(engine, rate)
    cpu_ms = 1e3 * (c1 - c0) / (last - WARM)
    pct = {q: float(np.percentile(lat, q)) for q in (50, 95, 99)}
    return {"frames": summary["frames"], "valid": summary["valid_frames"], "rate": rate,
            "achieved_fps": (last - WARM) / (w1 - w0), "cpu_ms_per_frame": cpu_ms,
            "share_of_two_cores": cpu_ms * rate / 2000.0, "model_cpu_ms_per_frame": model_cpu_ms,
            "cpu_over_model": cpu_ms / model_cpu_ms,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "latency_ms": pct, "faults": summary["faults"], "states_s": summary.get("states_s", {}),
            "stage_ms": {k: {q: float(np.percentile(v, q)) for q in (50, 95, 99)} for k, v in stage_ms.items()}}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("clip")
    p.add_argument("rate", type=float)
    p.add_argument("--calib")
    p.add_argument("--loops", type=int, default=1)
    p.add_argument("--runtime", default="{}", help="[runtime] settings as JSON, e.g. {\"opencv_threads\": 0}")
    a = p.parse_args()
    import bsn_edge

    row = worker(Path(a.clip), a.rate, a.calib, a.loops, json.loads(a.runtime))
    print(json.dumps({**row, "bsn_edge": str(Path(bsn_edge.__file__).parent)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
