"""Light on the car: the runtime's CPU per frame and its latency at the camera's own rate, not flat out.

    python -m bsn_edge.benchmarks.bench_footprint --out benchmarks/results [--code DIR ...]

A dashcam delivers 25-30 frames a second and the same two cores run the rest of the vehicle's software:
what an integrator budgets is how much of the two cores ``bsn-run`` takes at the camera's rate and how long a
frame takes from the camera to the bus. Each row is a fresh process running the runtime as ``bsn-run`` does
(the shipped int8 model, the vehicle file's defaults, a frame log and a CAN log on python-can's virtual
bus), on a real clip paced at 15 or 30 frames a second:

- the Udacity clip, 1280x720, with its camera file (the chessboard photos and the mounting step), played
  8 times over (``LOOPS``: 304 frames; its own codec decodes every frame; the first frame of each replay,
  which waits for the file to reopen, is left out of the latency figures, not of the CPU);
- the dashcam highway, 960x540, 221 frames, with no camera file (online calibration runs, as for a user
  who has none).

Figures: the process's CPU per frame (user + system from ``getrusage``, between frame ``WARM`` and the last,
so start-up is apart), its share of two cores at that rate, peak memory (``ru_maxrss``), latency from the
frame's decode to its cycle on the bus (the frame log's ``latency_ms``, p50/p95/p99) and per stage; beside
them the int8 model's own CPU per frame, measured in the same process after the run on the last frame,
paced at the same rate, its threads not spinning. ``--code`` runs the rows against other source trees too
(the code before a change, side by side in one sitting), each named by its commit.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bsn_edge.cli.common import CHECKOUT

from .real_samples import REAL
from .runner import Report, run

LOOPS = 8
RATES = (15.0, 30.0)
REPEATS = 2              # each tree's row twice, interleaved: the spread between the two is this VM's noise
WORKER = Path(__file__).with_name("footprint_worker.py")    # a script: it imports the tree it is given
CLIPS = {"udacity 1280x720, camera file": "udacity_test_video.mp4", "highway 960x540, no camera file":
         "dashcam_highway.mp4"}


def _commit(code: Path) -> str:
    r = subprocess.run(["git", "-C", str(code), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", str(code), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return (r.stdout.strip() or code.name) + ("+" if dirty else "")


def cpu_name() -> str:
    """The CPU's model and its int8 instruction sets (from /proc/cpuinfo)."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor() or "unknown CPU"
    model = next((ln.split(":", 1)[1].strip() for ln in info.splitlines() if ln.startswith("model name")), "?")
    flags = set(next((ln.split(":", 1)[1].split() for ln in info.splitlines() if ln.startswith("flags")), []))
    sets = [n for f, n in (("avx2", "AVX2"), ("avx512f", "AVX-512"), ("avx512_vnni", "VNNI"),
                           ("avx_vnni", "AVX-VNNI"), ("avx512_bf16", "AVX512-BF16"), ("amx_int8", "AMX")) if f in flags]
    return f"{model} ({', '.join(sets)}), {os.cpu_count()} cores"


def measure(args: argparse.Namespace, _p: argparse.ArgumentParser) -> Report | None:
    missing = [c for c in CLIPS.values() if not (REAL / c).exists()]
    if missing:
        print(f"no real clips {missing} in {REAL}: nothing to measure")
        return None
    from .real_samples import udacity_camera

    codes = [Path(c).resolve() for c in args.code] or [CHECKOUT]
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        calib = Path(tmp) / "udacity.json"
        udacity_camera()[1].write(calib)
        # the trees side by side row by row: a VM's speed drifts over minutes, and a tree measured after the
        # other would carry the drift
        for label, clip in CLIPS.items():
            for rate in RATES:
                for code in [c for _ in range(REPEATS) for c in codes]:
                    name = _commit(code)
                    env = {**os.environ, "PYTHONPATH": str(code)}      # the tree's bsn_edge, not the install's
                    argv = [sys.executable, str(WORKER), str(REAL / clip), str(rate), "--loops",
                            str(LOOPS if clip.startswith("udacity") else 1)]
                    if clip.startswith("udacity"):
                        argv += ["--calib", str(calib)]
                    out = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=tmp, check=True).stdout
                    row = {"code": name, "clip": label, **json.loads(out.strip().splitlines()[-1])}
                    if not Path(row["bsn_edge"]).resolve().is_relative_to(code):
                        raise RuntimeError(f"the worker ran {row['bsn_edge']}, not {code}'s bsn_edge")
                    rows.append(row)
                    print(f"{name} {label} {rate:g}/s: {row['cpu_ms_per_frame']:.1f} ms CPU a frame "
                          f"({row['cpu_over_model']:.2f}x the model's {row['model_cpu_ms_per_frame']:.1f}), "
                          f"latency p99 {row['latency_ms']['99']:.1f} ms", flush=True)
    md = ["# Light on the car: CPU and latency at the camera's rate", "",
          f"Measured on {cpu_name()}, onnxruntime with `intra_op_num_threads=2`, nothing else running; "
          f"{time.strftime('%Y-%m-%d')}. Each row a fresh process (the runtime as `bsn-run` runs it, the shipped "
          "int8 model, a frame log and a CAN log); CPU per frame from `getrusage` between frame "
          "20 and the last (footprint_worker.WARM); the model's own in the same process, paced the same, not "
          "spinning.", "",
          "| code | clip | rate | CPU per frame | the model's own | ratio | share of 2 cores | latency p50 / p95 / p99 "
          "| peak memory |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lat = r["latency_ms"]
        md.append(f"| {r['code']} | {r['clip']} | {r['rate']:g}/s | {r['cpu_ms_per_frame']:.1f} ms | "
                  f"{r['model_cpu_ms_per_frame']:.1f} ms | {r['cpu_over_model']:.2f}x | "
                  f"{100 * r['share_of_two_cores']:.0f} % | {lat['50']:.1f} / {lat['95']:.1f} / {lat['99']:.1f} ms | "
                  f"{r['peak_rss_mb']:.0f} MB |")
    md += ["", "Per stage, p50 / p99 ms (30 frames a second):", "",
           "| code | clip | " + " | ".join(STAGES) + " |", "|---|---|" + "---|" * len(STAGES)]
    for r in rows:
        if r["rate"] == 30.0:
            md.append(f"| {r['code']} | {r['clip']} | " + " | ".join(
                f"{r['stage_ms'][s]['50']:.2f} / {r['stage_ms'][s]['99']:.2f}" if s in r["stage_ms"] else "-"
                for s in STAGES) + " |")
    md += ["", "Targets at 30 frames a second, 1280x720: CPU per frame at most 1.4x the model's own; latency p99 at "
           "most 12 ms.", "", "Clips: `../shared/data/real` (their sources and licences in its README)."]
    return Report({"cpu": cpu_name(), "rows": rows}, md, [f"{len(rows)} rows"])


STAGES = ("decode", "preprocess", "visibility", "inference", "postprocess", "send")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="footprint", help="the report's name in --out")
    p.add_argument("--code", nargs="*", default=[], metavar="DIR",
                   help="source trees to measure side by side (default: this checkout)")
    return p


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
