"""What the camera's pace costs before any of the runtime's own work: the floors under the footprint's targets.

    python -m bsn_edge.benchmarks.bench_paced_floor --out benchmarks/results

``bench_footprint`` measures the whole runtime at 15 and 30 frames a second. This one takes its two
largest parts alone, in one process, nothing else in it, so the rest of the runtime cannot be blamed:

- **the int8 model alone** (the shipped one, ``intra_op_num_threads=2``, one input): flat out, then paced at
  30 frames a second the way a camera paces it (the thread sleeps until the next frame), with onnxruntime's
  threads not spinning (the runtime's setting), spinning, and not spinning while this thread busy-waits
  instead of sleeping (the cores are kept awake between frames, as another busy process would keep them).
  Wall time per inference p50 / p99 and the process's CPU per frame (``getrusage``; the busy wait's own CPU
  included, which is the point of that row);
- **decoding** the real 1280x720 clip (H.264, FFmpeg through OpenCV, one decoding thread as
  ``bsn-run`` opens a file): CPU per frame, the same clip read ``LOOPS`` times.

Each row ``ROUNDS`` times in alternation, in fresh sessions; the median of the rounds is reported with the
range.
"""

from __future__ import annotations

import argparse
import resource
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .bench_footprint import cpu_name
from .real_samples import REAL
from .runner import Report, run

RATE = 30.0              # frames a second
FRAMES = 150             # inferences per row and round (5 s at 30 frames a second)
WARM = 10                # inferences before a row's timing
ROUNDS = 3
LOOPS = 4                # the 38-frame clip decoded this many times per round
CLIP = "udacity_test_video.mp4"


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _session(spin: bool):
    import onnxruntime as ort

    from bsn_edge.default_model import DEFAULT_MODEL

    so = ort.SessionOptions()
    so.intra_op_num_threads, so.inter_op_num_threads = 2, 1
    so.add_session_config_entry("session.intra_op.allow_spinning", "1" if spin else "0")
    return ort.InferenceSession(str(DEFAULT_MODEL), so, providers=["CPUExecutionProvider"])


def _model_row(spin: bool, pace: str) -> dict[str, float]:
    """One row's round: ``pace`` is "flat out", "sleep" or "busy wait"."""
    s = _session(spin)
    inp = s.get_inputs()[0]
    x = np.random.default_rng(0).integers(0, 255, [d if isinstance(d, int) else 1 for d in inp.shape], np.uint8)
    for _ in range(WARM):
        s.run(None, {inp.name: x})
    period = 1.0 / RATE
    walls = []
    c0 = _cpu()
    for _ in range(FRAMES):
        t = time.perf_counter()
        s.run(None, {inp.name: x})
        walls.append(time.perf_counter() - t)
        left = period - walls[-1]
        if pace == "sleep" and left > 0:
            time.sleep(left)
        elif pace == "busy wait":
            end = time.perf_counter() + left
            while time.perf_counter() < end:
                pass
    w = 1e3 * np.array(walls)
    return {"p50_ms": float(np.percentile(w, 50)), "p99_ms": float(np.percentile(w, 99)),
            "cpu_ms": 1e3 * (_cpu() - c0) / FRAMES}


def _decode_row() -> dict[str, float]:
    import cv2

    c0, n = _cpu(), 0
    for _ in range(LOOPS):
        cap = cv2.VideoCapture(str(REAL / CLIP), cv2.CAP_FFMPEG, [cv2.CAP_PROP_N_THREADS, 1])
        while cap.read()[0]:
            n += 1
        cap.release()
    return {"cpu_ms": 1e3 * (_cpu() - c0) / max(n, 1), "frames": n}


ROWS: dict[str, Callable[[], dict[str, float]]] = {
    "model, flat out, threads not spinning": lambda: _model_row(False, "flat out"),
    "model, 30/s, threads not spinning (the runtime's)": lambda: _model_row(False, "sleep"),
    "model, 30/s, threads spinning": lambda: _model_row(True, "sleep"),
    "model, 30/s, not spinning, this thread busy-waits between frames": lambda: _model_row(False, "busy wait"),
    "decode 1280x720 H.264, one thread": _decode_row,
}


def _median(rounds: list[dict[str, float]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k in rounds[0]:
        v = [r[k] for r in rounds]
        out[k] = {"median": float(np.median(v)), "min": float(min(v)), "max": float(max(v))}
    return out


def measure(args: argparse.Namespace, _p: argparse.ArgumentParser) -> Report | None:
    if not (REAL / CLIP).exists():
        print(f"no real clip {CLIP} in {REAL}: nothing to measure")
        return None
    got: dict[str, list[dict[str, float]]] = {k: [] for k in ROWS}
    for k in range(ROUNDS):
        for name, row in ROWS.items():          # alternated: a VM's drift spreads over every row alike
            got[name].append(row())
            print(f"round {k + 1}/{ROUNDS}: {name}: {got[name][-1]}", flush=True)
    rows = {name: _median(r) for name, r in got.items()}

    def cell(name: str, key: str) -> str:
        v = rows[name].get(key)
        return "-" if v is None else f"{v['median']:.2f} ({v['min']:.2f}-{v['max']:.2f})"

    md = ["# The floors under the footprint's targets", "",
          f"Measured on {cpu_name()}, onnxruntime with `intra_op_num_threads=2`, nothing else running; "
          f"{time.strftime('%Y-%m-%d')}. The median of {ROUNDS} rounds, rows in alternation, with the range; "
          f"{FRAMES} inferences per row and round; CPU from `getrusage` (the busy wait's own included).", "",
          "| what | wall p50 ms | wall p99 ms | CPU per frame ms |", "|---|---|---|---|"]
    md += [f"| {name} | {cell(name, 'p50_ms')} | {cell(name, 'p99_ms')} | {cell(name, 'cpu_ms')} |" for name in ROWS]
    md += ["", f"Decoding: `{CLIP}` ({rows['decode 1280x720 H.264, one thread']['frames']['median']:.0f} frames a "
           "round), through OpenCV's FFmpeg as `bsn-run` opens a file.", "",
           "Read against the targets (30 frames a second, 1280x720): the model's own CPU is the runtime's floor, "
           "and decoding alone adds the ratio in the last row over it; the latency target is to be compared with "
           "the model's own p99 when paced as a camera paces it."]
    return Report({"cpu": cpu_name(), "rows": rows}, md)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="paced_floor", help="the report's name in --out")
    return p


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
