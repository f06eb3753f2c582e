"""Structured pruning at export: what it removes, that the outputs stay, and what it saves, side by side.

    python -m bsn_edge.benchmarks.bench_prune --out benchmarks/results [--run models/default] [--frames VIDEO]

The run is exported twice in one sitting, int8 with 7-bit weights on the same calibration frames (frames
of a real drive): once as ``bsn-export`` does by default (``export.prune``: the convolution
channels nothing reads taken out of the graph) and once with ``--no-prune``. Reported:

- convolution channels and multiply-accumulates in each graph, and the file sizes;
- how far the pruned graph's outputs stray from the unpruned one's on real frames, fp32 and int8
  (probability, mask agreement at the card's threshold, depth);
- model-only milliseconds of both with the runtime's session (2 intra-op threads), alternating rounds,
  and the ratio; with the model-only rate measured for the unpruned graph on a CPU without VNNI
  (``runtime_avx2_shared``), the rate derived there for the pruned one (derived, not measured).
"""

from __future__ import annotations

import argparse
import io
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.cli.common import CHECKOUT
from bsn_edge.export.calib_frames import load_frames
from bsn_edge.export.pipeline import compare, export_run
from bsn_edge.modelfile.read import session

from . import runner
from .common import summary, time_calls
from .runner import Report

DRIVE = CHECKOUT.parent / "shared" / "data" / "real" / "udacity_test_video.mp4"
AVX2_REPORT = CHECKOUT / "benchmarks" / "results" / "runtime_avx2_shared.json"
ROUNDS, CALLS = 6, 20


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", default=str(CHECKOUT / "models" / "default"),
                   help="a trained run (default: the shipped one's)")
    p.add_argument("--frames", default=str(DRIVE), help="a real drive: calibration and comparison frames")
    p.add_argument("--calib", type=int, default=32, help="calibration frames (default 32)")
    p.add_argument("--compare", type=int, default=64, help="frames the outputs are compared on (default 64)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="prune", help="the report's name in --out")
    return p


def _avx2_model_only(name: str = "shared_light_int8.onnx") -> tuple[float, str] | None:
    """The unpruned shipped architecture's model-only frames/s measured on a CPU without VNNI."""
    if not AVX2_REPORT.is_file():
        return None
    rec = json.loads(AVX2_REPORT.read_text())
    rates = [r["model_only_fps"] for r in rec.get("rows", []) if r.get("model_file") == name]
    if not rates:
        return None
    return float(np.median(rates)), rec.get("machine", {}).get("cpu", "?")


def _markdown(run: Path, drive: Path, calib: int, compared: int, pruned: dict[str, Any], sizes: dict[str, int],
              rates: dict[str, Any], speedup: float, same: dict[str, Any], avx2: tuple[float, str] | None) -> list[str]:
    """The report's page."""
    md = [
        "# Structured pruning at export", "",
        f"Run `{run.name}` exported twice in one sitting, int8 (7-bit weights) calibrated on {calib} frames of "
        f"`{drive.name}`; outputs compared on {compared} frames sampled evenly through it. Model only, "
        f"runtime session, 2 intra-op threads, alternating rounds ({ROUNDS} x {CALLS} calls each).", "",
        "| graph | convolution channels | GMACs | int8 file | median ms | frames/s |", "|---|---|---|---|---|---|",
        f"| unpruned (`--no-prune`) | {pruned['channels_before']:,} | {pruned['macs_before'] / 1e9:.2f} | "
        f"{sizes['unpruned'] / 1e6:.1f} MB | {rates['unpruned']['median_ms']:.2f} | "
        f"{rates['unpruned']['per_second']:.1f} |",
        f"| pruned (default) | {pruned['channels_after']:,} | {pruned['macs_after'] / 1e9:.2f} | "
        f"{sizes['pruned'] / 1e6:.2f} MB | {rates['pruned']['median_ms']:.2f} | "
        f"{rates['pruned']['per_second']:.1f} |",
        "", f"Speed-up {speedup:.2f}x.", "",
        "| pruned vs unpruned | max abs probability | mask agreement | depth rel. difference, median / max |",
        "|---|---|---|---|",
        *(f"| {k} | {v['max_abs_prob']:.2e} | {100 * v['mask_agreement']:.3f} % | "
          f"{v['depth_median_rel']:.1e} / {v['depth_max_rel']:.1e} |"
          for k, v in same.items()),
        "", "fp32 differs only by float summation order; int8 also by the calibration ranges, which the removed "
        "channels no longer take part in.",
    ]
    if avx2 is not None:
        md += ["", f"Derived, not measured: on {avx2[1]} (no VNNI) the unpruned graph ran {avx2[0]:.1f} model-only "
               f"frames/s (`runtime_avx2_shared`); at this sitting's ratio the pruned one would run "
               f"{avx2[0] * speedup:.0f}."]
    return md


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    run, drive = Path(args.run), Path(args.frames)
    for what in (run, drive):
        if not what.exists():
            print(f"{p.prog}: {what} is absent here; nothing measured")
            return None
    outs: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        paths = {k: Path(tmp) / f"{k}.onnx" for k in ("pruned", "unpruned")}
        fp32 = {k: Path(tmp) / f"{k}_fp32.onnx" for k in paths}
        for k in paths:
            outs[k] = export_run(run, paths[k], int8=True, calib=drive, calib_frames=args.calib,
                                 prune_dead=k == "pruned", log=io.StringIO())
            export_run(run, fp32[k], prune_dead=k == "pruned", log=io.StringIO())
        card = outs["pruned"]["card"]
        frames = load_frames(drive, tuple(card["input_size"]), args.compare)
        sessions = {k: session(v) for k, v in paths.items()}
        same = {"int8": compare(paths["unpruned"], paths["pruned"], frames, card["threshold"]),
                "fp32": compare(fp32["unpruned"], fp32["pruned"], frames, card["threshold"])}
        sizes = {k: v.stat().st_size for k, v in paths.items()}
        frame = frames[:1]
        times: dict[str, list[float]] = {k: [] for k in sessions}
        for _ in range(ROUNDS):
            for k, s in sessions.items():
                times[k] += time_calls(lambda i, s=s: s.run(None, {"frame": frame}), CALLS)  # type: ignore[misc]
    rates = {k: summary(v) for k, v in times.items()}
    pruned = outs["pruned"]["pruned"]
    speedup = rates["unpruned"]["median_ms"] / rates["pruned"]["median_ms"]
    avx2 = _avx2_model_only()
    result: dict[str, Any] = {"run": str(run), "frames": str(drive), "compared_frames": len(frames),
                              "pruned": pruned, "bytes": sizes, "same_outputs": same, "rates": rates,
                              "speedup": speedup}
    if avx2 is not None:
        result["avx2_derived"] = {"unpruned_measured_fps": avx2[0], "cpu": avx2[1],
                                  "pruned_derived_fps": avx2[0] * speedup}
    md = _markdown(run, drive, args.calib, len(frames), pruned, sizes, rates, speedup, same, avx2)
    return Report(result, md, md)


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
