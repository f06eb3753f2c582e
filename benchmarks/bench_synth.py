"""Rendering speed of the synthetic world at 256x512, BS-GT included.

    python -m benchmarks.bench_synth --out benchmarks/results
"""

from __future__ import annotations

import argparse

from benchmarks.common import summary, time_calls, write_result
from bsn_edge.synth import STYLES, Renderer, SynthConfig, make_clip

BAR_FPS = 20.0
GOAL_FPS = 50.0


def run(frames: int = 100, height: int = 256, width: int = 512) -> dict:
    rows = []
    for style in sorted(STYLES):
        clip = make_clip(SynthConfig(frames=frames, height=height, width=width, style=style, seed=0))
        r = Renderer(clip.lens.canvas, far=clip.config.far, bs_range=clip.config.bs_range)
        world = clip.scenario.world

        def one(i, r=r, world=world, clip=clip):
            r.render(world, clip.poses[i], float(clip.times[i]), i)
        s = summary(time_calls(one, frames, warmup=0))
        rows.append({"style": style, "height": height, "width": width, **s})
    fps = min(r["per_second"] for r in rows)
    return {"rows": rows, "min_fps": fps, "bar_fps": BAR_FPS, "goal_fps": GOAL_FPS,
            "passes_bar": fps >= BAR_FPS}


def markdown(res: dict) -> str:
    lines = ["# Synthetic world: rendering speed", "",
             "RGB, depth, semantics and true blind spots per frame, one process, median over the clip.", "",
             "| style | size | median ms/frame | p95 ms | frames/s |", "|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['style']} | {r['height']}x{r['width']} | {r['median_ms']:.1f} | "
                     f"{r['p95_ms']:.1f} | {r['per_second']:.1f} |")
    lines += ["", f"Bar >= {res['bar_fps']:g} frames/s, goal {res['goal_fps']:g}: slowest style "
              f"{res['min_fps']:.1f} frames/s ({'passes' if res['passes_bar'] else 'FAILS'})."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--frames", type=int, default=100)
    args = p.parse_args(argv)
    res = run(args.frames)
    path = write_result(args.out, "synth", res, markdown(res))
    print(markdown(res))
    print(f"wrote {path}")
    return 0  # a missed bar is a finding in the report, not a crash of the benchmark run


if __name__ == "__main__":
    raise SystemExit(main())
