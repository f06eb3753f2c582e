"""Rendering speed of the synthetic world at 256x512: true labels and sensor effects included.

    python -m bsn_edge.benchmarks.bench_synth --out benchmarks/results

Per style: the ray caster alone in one process (median ms per frame), then what ``bsn-synth``
does per frame (ray casting, lens, sensor effects, hood) through ``render_frames`` in one
process and in two, as frames per second of wall time over the clip. The bar is on two workers,
because ``bsn-synth`` renders in two processes on a 2-core machine by default.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

from bsn_edge.synth import STYLES, Renderer, SynthConfig, make_clip
from bsn_edge.synth.clip import render_frames

from . import runner
from .common import summary, time_calls
from .runner import Report

BAR_FPS = 20.0
WORKERS = (1, 2)


def _throughput(clip, workers: int) -> float:
    t0 = time.perf_counter()
    n = sum(1 for _ in render_frames(clip, workers=workers))
    return n / (time.perf_counter() - t0)


def run(frames: int = 100, height: int = 256, width: int = 512) -> dict:
    rows = []
    for style in sorted(STYLES):
        clip = make_clip(SynthConfig(frames=frames, height=height, width=width, style=style, seed=0))
        r = Renderer(clip.lens.canvas, far=clip.config.far, bs_range=clip.config.bs_range)
        world = clip.scenario.world

        def one(i, r=r, world=world, clip=clip):
            r.render(world, clip.poses[i], float(clip.times[i]), i)
        s = summary(time_calls(one, frames, warmup=0))
        row: dict[str, Any] = {"style": style, "height": height, "width": width, "render_median_ms": s["median_ms"],
               "render_p95_ms": s["p95_ms"]}
        for w in WORKERS:
            row[f"fps_workers_{w}"] = _throughput(clip, w)
        rows.append(row)
    fps = min(r[f"fps_workers_{WORKERS[-1]}"] for r in rows)
    return {"rows": rows, "min_fps": fps, "bar_fps": BAR_FPS, "bar_workers": WORKERS[-1],
            "passes_bar": fps >= BAR_FPS}


def markdown(res: dict) -> str:
    head = " | ".join(f"frames/s, {w} worker{'s' if w > 1 else ''}" for w in WORKERS)
    lines = ["# Synthetic world: rendering speed", "",
             "Ray casting alone (one process, median over the clip), then the whole `bsn-synth` frame "
             "(RGB, depth, semantics, true blind spots, lens, sensor effects, hood) through "
             "`render_frames`, frames per second of wall time.", "",
             f"| style | size | ray casting ms/frame | p95 ms | {head} |",
             "|---|---|---|---|" + "---|" * len(WORKERS)]
    for r in res["rows"]:
        fps = " | ".join(f"{r[f'fps_workers_{w}']:.1f}" for w in WORKERS)
        lines.append(f"| {r['style']} | {r['height']}x{r['width']} | {r['render_median_ms']:.1f} | "
                     f"{r['render_p95_ms']:.1f} | {fps} |")
    lines += ["", f"Bar >= {res['bar_fps']:g} frames/s with {res['bar_workers']} workers: slowest style "
              f"{res['min_fps']:.1f} frames/s ({'passes' if res['passes_bar'] else 'FAILS'})."]
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--frames", type=int, default=100)
    p.add_argument("--name", default="synth", help="the report's name in --out")
    return p


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    res = run(args.frames)
    return Report(res, [markdown(res)], [markdown(res)])


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
