"""Accuracy against speed: held-out IoU over model-only frames/s of exported models, on one plot.

    python -m bsn_edge.benchmarks.bench_tradeoff --model "default=bsn_edge/default_model/bsn_shared_light_int8.onnx" \\
        --model "shared=RUN/model_int8.onnx" [--cameras benchmarks/results/cameras.json] --out benchmarks/results

Speed: every model opened as ``bsn-run`` opens it (:class:`~bsn_edge.runtime.engine.Engine`, 2
intra-op threads, the kernels its card asks for), timed one inference at a time in alternation
(one run of each model per round), so the machine's drift falls on all alike; the median of the
rounds. GMACs from the graph's convolutions. Accuracy: each model's held-out IoU per set as
``bench_cameras`` measured it (its report, by the same model name), so nothing is evaluated twice.
The report is named by CPU class (``tradeoff`` with VNNI, ``tradeoff_avx2`` without).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: before pyplot is imported
import matplotlib.pyplot as plt
import numpy as np

from bsn_edge.runtime.engine import Engine

from . import runner
from .bench_floor import conv_kinds
from .common import class_name, cpu_named, machine
from .runner import Report


def alternated(engines: dict[str, Engine], runs: int, warmup: int = 5) -> dict[str, list[float]]:
    """Seconds per inference of every engine, one run of each per round, ``runs`` rounds."""
    rng = np.random.default_rng(0)
    frames = {k: rng.integers(0, 256, (1, *e.card.input_size, 3), dtype=np.uint8) for k, e in engines.items()}
    times: dict[str, list[float]] = {k: [] for k in engines}
    for i in range(warmup + runs):
        for k, e in engines.items():
            t0 = time.perf_counter()
            e.infer(frames[k])
            if i >= warmup:
                times[k].append(time.perf_counter() - t0)
    return times


def gmacs(path: Path) -> float:
    return sum(macs for _, macs in conv_kinds(path).values()) / 1e9


def plot(rows: list[dict[str, Any]], sets: list[str], path: Path, title: str) -> None:
    fig, ax = plt.subplots(figsize=(7, 5))
    for r in rows:
        ious = [r["iou"][s] for s in sets if s in r["iou"]]
        if not ious:
            continue
        ax.errorbar(r["fps"], np.mean(ious), yerr=[[np.mean(ious) - min(ious)], [max(ious) - np.mean(ious)]],
                    fmt="o", capsize=4)
        ax.annotate(f"{r['model']} ({r['gmacs']:.2f} GMACs)", (r["fps"], np.mean(ious)), textcoords="offset points",
                    xytext=(6, 6), fontsize=9)
    ax.set_xlabel("model-only frames/s (int8, 2 threads)")
    ax.set_ylabel("held-out IoU (mean; bar: lowest to highest set)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", action="append", required=True, metavar="NAME=MODEL.onnx",
                   help="an exported model, named as in the cameras report")
    p.add_argument("--cameras", default="benchmarks/results/cameras.json",
                   help="bench_cameras' report holding each model's held-out IoU (default: %(default)s)")
    p.add_argument("--runs", type=int, default=200, help="rounds of alternated inferences (default 200)")
    p.add_argument("--out", default="benchmarks/results")
    return p


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    named = [(spec.partition("=")[0], Path(spec.partition("=")[2])) for spec in args.model]
    if any(not name or not path.name for name, path in named):
        p.error("--model wants NAME=MODEL.onnx")
    cameras = json.loads(Path(args.cameras).read_text()) if Path(args.cameras).is_file() else {"models": {}, "sets": {}}
    sets = list(cameras.get("sets", {}))
    engines = {name: Engine(path, threads=2) for name, path in named}
    times = alternated(engines, args.runs)
    rows = []
    for name, path in named:
        ms = 1e3 * float(np.median(times[name]))
        acc = cameras["models"].get(name, {})
        rows.append({"model": name, "file": str(path), "variant": engines[name].card.variant, "gmacs": gmacs(path),
                     "median_ms": ms, "fps": 1e3 / ms, "kernels": engines[name].kernels,
                     "iou": {s: acc[s]["iou"] for s in sets if s in acc}})
    report = class_name("tradeoff")
    figure = f"{report}.png"
    Path(args.out).mkdir(parents=True, exist_ok=True)
    plot(rows, sets, Path(args.out) / figure, f"{cpu_named(machine())}, 2 cores")
    lines = ["# Held-out IoU against model-only frames/s", "",
             f"Every model as `bsn-run` opens it, 2 intra-op threads, {args.runs} rounds of one inference each "
             "in alternation (median); held-out IoU from `bench_cameras` (`cameras.md`).", "",
             f"![IoU against frames/s]({figure})", "",
             "| model | variant | GMACs | median ms | frames/s | " + " | ".join(f"IoU {s}" for s in sets) + " |",
             "|---|---|---|---|---|" + "---|" * len(sets)]
    for r in rows:
        ious = " | ".join(f"{r['iou'][s]:.3f}" if s in r["iou"] else "-" for s in sets)
        lines.append(f"| {r['model']} | {r['variant']} | {r['gmacs']:.2f} | {r['median_ms']:.2f} | {r['fps']:.1f} | "
                     f"{ious} |")
    base = rows[0]
    lines += ["", *[f"- {r['model']}: {base['median_ms'] / r['median_ms']:.2f}x the frames/s of {base['model']}"
                    for r in rows[1:]]]
    return Report({"models": rows, "sets": sets, "runs": args.runs}, lines, lines, name=report)


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
