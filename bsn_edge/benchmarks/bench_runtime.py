"""End-to-end latency profile of the edge loop against the model alone, side by side in one run.

    python -m bsn_edge.benchmarks.bench_runtime [--model A.onnx --model B.onnx] [--source VIDEO[=CALIB.json]] \\
        --frames 300 --out benchmarks/results

End to end: ``bsn-run``'s loop on the clip (decode, warp into the model camera, inference,
sectors, smoothing, alert state, CAN encoding and sending on a virtual bus), 2 intra-op threads,
start-up excluded, once with the clip's camera file and once with none (online calibration, as
``bsn-run`` does without ``--calib``; it runs beside the frame path). Model only: the same session
on the same frames, back to back. Without ``--source``, the real clips of ``../shared/data/real``:
the Udacity 1280x720 clip (its camera file from the chessboard photos and the product's mounting
step) and the 960x540 highway clip (no camera file: online calibration only). A clip shorter than
``--frames`` is played forwards then backwards until long enough and re-encoded (MPEG-4 part 2:
its decode time is not the original's H.264).

Each clip is run in every way the loop can be set (``--loops``), side by side: reading in turn with
the model or overlapped with it (``RuntimeConfig.overlap``: decode and warp of the next frame on a
thread of their own), onnxruntime's idle threads spinning or not (``bsn-run --no-spin``), and two
frames in flight on one-thread engines (``bsn-run --in-flight 2``). Model only is always the
two-thread engine, one frame at a time: the model's own rate as the default runs it. With
overlap the stage times are work per frame on two threads: they add up to more than the frame's
wall time.

Then, as a car runs it, each clip delivered like a camera (a frame every 1 / its frame rate, read by
``bsn-run``'s live source, which keeps only the newest frame) through the default loop, with the
camera file and calibrating: whether the loop keeps up (frames dropped), its latency, and where
online calibration stands at the end.

Last, where a frame's CPU goes: reading (decode, warp, online calibration) and the model, each timed
alone in CPU time of every thread, and the ceiling they leave end to end on 2 cores (both must be
done for every frame): what the >= 90 % bar can reach on this machine at all.

``--repeats N`` runs the whole matrix N times over (a shared machine's speed drifts between
minutes): the summary table gives each row's median over the runs and judges the bars on it.
The report is ``runtime`` on a CPU with VNNI, ``runtime_avx2`` on AVX2 without it (``--name``
chooses another), so one CPU class's results do not overwrite another's.

Bars (issue: real time on every 2-core CPU): end to end >= 30 frames/s (>= 60 on a CPU with VNNI),
>= 90 % of the model's own frames/s, p99 <= 2x p50.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2

from bsn_edge.alerts.can_output import CanSender
from bsn_edge.calibration import Calibration
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.runtime import Engine, RuntimeConfig, open_source, run
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.live_source import LiveSource, Reconnect
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.media import read_video

from . import runner
from .common import class_name, machine, summary, time_calls
from .real_samples import REAL, udacity_camera
from .runner import Report
from .runtime_budget import SHARE_BAR, budget_table, cpu_budget

FPS_BAR, FPS_BAR_VNNI = 30.0, 60.0
TAIL_BAR = 2.0


def model_only(engine: Engine, video: str, frames: int, camera: CameraState) -> float:
    batches = [camera.frame_for(f).to_model(f)[None] for f in read_video(video, frames)]
    return summary(time_calls(lambda i: engine.infer(batches[i]), len(batches), warmup=5))["per_second"]


def lengthen(video: Path, frames: int, tmp: Path) -> Path:
    """``video`` itself when it holds ``frames``, else forwards-backwards copies of it re-encoded."""
    cap = cv2.VideoCapture(str(video))
    n, fps = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), cap.get(cv2.CAP_PROP_FPS) or 25.0
    cap.release()
    if n >= frames:
        return video
    clip = read_video(video)
    out = tmp / f"{video.stem}_x{frames}.mp4"
    h, w = clip[0].shape[:2]
    wr = cv2.VideoWriter(str(out), cv2.VideoWriter.fourcc(*"mp4v"), fps, (w, h))
    k, direction = 0, 1
    for _ in range(frames):
        wr.write(clip[k])
        if not 0 <= k + direction < len(clip):
            direction = -direction
        k += direction
    wr.release()
    return out


@dataclass(frozen=True)
class Loop:
    """One way of setting the loop: reading overlapped with the model (its thread ``nice`` steps below
    the model's), onnxruntime's threads spinning."""

    overlap: bool
    spin: bool
    nice: int = 0
    decode_threads: int = 1      # FFmpeg's (0: its own choice, frame threads on every core)
    in_flight: int = 1           # frames in the model at once, on engines of one thread each when > 1

    @property
    def name(self) -> str:
        reading = "in turn" if not self.overlap else f"overlap{f' nice {self.nice}' if self.nice else ''}"
        decode = "" if self.decode_threads == 1 else f", decode {self.decode_threads or 'FFmpeg'} threads"
        flight = "" if self.in_flight == 1 else f", {self.in_flight} in flight"
        return f"{reading}, {'spin' if self.spin else 'no spin'}{decode}{flight}"

    def config(self) -> RuntimeConfig:
        return RuntimeConfig(overlap=self.overlap, feeder_nice=self.nice, in_flight=self.in_flight)


_DEFAULT = RuntimeConfig()
LOOPS = {"all": [Loop(o, sp) for o in (False, True) for sp in (True, False)] + [Loop(True, False, 10),
                                                                                 Loop(True, False, 10, in_flight=2)],
         "flight": [Loop(_DEFAULT.overlap, False, _DEFAULT.feeder_nice),
                    Loop(_DEFAULT.overlap, False, _DEFAULT.feeder_nice, in_flight=2)],
         "reading": [Loop(False, False), Loop(True, False), Loop(True, False, 10), Loop(True, False, 19)],
         "default": [Loop(_DEFAULT.overlap, False, _DEFAULT.feeder_nice)],
         "decode": [Loop(_DEFAULT.overlap, False, _DEFAULT.feeder_nice, 0), Loop(_DEFAULT.overlap, False,
                                                                                 _DEFAULT.feeder_nice)]}


class CameraLike:
    """A video file delivered as a camera delivers it: the next frame no sooner than 1 / fps after the
    one before (the ``opener`` of a :class:`LiveSource`)."""

    def __init__(self, path: str) -> None:
        self.cap = cv2.VideoCapture(path)
        self.period = 1.0 / (self.cap.get(cv2.CAP_PROP_FPS) or 25.0)
        self.due: float | None = None

    def isOpened(self) -> bool:
        return self.cap.isOpened()

    def get(self, prop: int) -> float:
        return self.cap.get(prop)

    def read(self):
        now = time.monotonic()
        self.due = now if self.due is None else self.due
        if self.due > now:
            time.sleep(self.due - now)
        self.due += self.period
        return self.cap.read()

    def release(self) -> None:
        self.cap.release()


def live(engine: Engine, video: Path, calibration: Calibration | None) -> dict[str, Any]:
    """The clip as a camera through the default loop: frames delivered, processed and dropped."""
    source = LiveSource(str(video), Reconnect(max_tries=0), opener=CameraLike)
    camera = CameraState(engine.card, calibration)
    try:
        with CanSender("virtual", "bsn-bench") as tx:
            s = run(engine, source, [tx], RuntimeConfig(), camera=camera)
    finally:
        source.close()
    cal = s["camera"]["calibration"]
    return {"frames": s["frames"], "dropped": s["dropped"], "before_start": s["before_start"],
            "e2e_fps": s["fps"], "p50_ms": s["p50_ms"],
            "p99_ms": s["p99_ms"], "wait_ms": s["wait_ms"], "camera_fps": source.fps,
            "calibrated": not s["camera"]["calibrating"], "calibration_pairs": cal.get("used"),
            "calibration_skipped": s["camera"]["estimator_skipped"]}


def profile(engine: Engine, video: Path, frames: int, calibration: Calibration | None, loop: Loop) -> dict[str, Any]:
    camera = CameraState(engine.card, calibration)
    with CanSender("virtual", "bsn-bench") as tx:
        s = run(engine, open_source(str(video), decode_threads=loop.decode_threads), [tx], loop.config(),
                max_frames=frames, camera=camera)
    return {"frames": s["frames"], "e2e_fps": s["fps"], "p50_ms": s["p50_ms"], "p95_ms": s["p95_ms"],
            "p99_ms": s["p99_ms"], "wait_ms": s["wait_ms"], "stage_ms": s["stage_ms"], "dropped": s["dropped"],
            "camera": s["camera"], "model": s["model"], "loop": loop.name, "overlap": loop.overlap, "spin": loop.spin,
            "feeder_nice": loop.nice}


def median_table(rows: list[dict[str, Any]], repeats: int, fps_bar: float) -> list[str]:
    """Markdown: each (clip, model, camera, loop)'s median over the repeats, bars judged on the medians
    (nothing with one run)."""
    if repeats < 2:
        return []
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["clip"], r["model_file"], r["camera_file"], r["loop"]), []).append(r)
    out = [f"## Medians of {repeats} runs of the matrix below", "",
           "| clip | model | camera | loop | end to end frames/s (runs) | model only frames/s (runs) | ratio | "
           "p99 / p50 | bars |", "|---|---|---|---|---|---|---|---|---|"]
    for (clip, model, cam, loop), rs in groups.items():
        e2e, mo = [r["e2e_fps"] for r in rs], [r["model_only_fps"] for r in rs]
        e, m = statistics.median(e2e), statistics.median(mo)
        tail = statistics.median(r["p99_over_p50"] for r in rs)
        fails = [k for k, ok in (("fps", e >= fps_bar), ("share", e / m >= SHARE_BAR), ("tail", tail <= TAIL_BAR))
                 if not ok]
        out.append(f"| {clip} | {model} | {'file' if cam else 'calibrating'} | {loop} | {e:.1f} "
                   f"({' / '.join(f'{v:.1f}' for v in e2e)}) | {m:.1f} ({' / '.join(f'{v:.1f}' for v in mo)}) | "
                   f"{100 * e / m:.0f} % | {tail:.2f} | {'pass' if not fails else 'FAIL: ' + ', '.join(fails)} |")
    return [*out, "", "## Every run", ""]


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", action="append", help="models side by side (default: the shipped one)")
    p.add_argument("--source", action="append", metavar="VIDEO[=CALIB.json]",
                   help="a video, with its camera file if it has one (default: the real clips)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--repeats", type=int, default=1, help="runs of the whole matrix; the summary takes medians")
    p.add_argument("--name", help="the report's name in --out (default: runtime with VNNI, runtime_avx2 on AVX2 "
                                  "without it)")
    p.add_argument("--loops", choices=sorted(LOOPS), default="all",
                   help="every way of setting the loop side by side, the ways of reading (no spin), FFmpeg's "
                        "decoding threads against one (decode), two frames in flight against one (flight), or "
                        "only bsn-run's default (default: all)")
    return p


def _clips(args: argparse.Namespace) -> list[tuple[str, Path, Calibration | None]]:
    """The videos asked for with their camera files (beside them when not named), else the real clips."""
    clips: list[tuple[str, Path, Calibration | None]] = []
    for spec in args.source or []:
        video, _, cal = spec.partition("=")
        own = Path(video).parent / SequenceFolder.CALIBRATION
        cal_path = Path(cal) if cal else (own if own.is_file() else None)
        clips.append((Path(video).name, Path(video), Calibration.read(cal_path) if cal_path else None))
    if not args.source:
        if not (REAL / "udacity_test_video.mp4").is_file():
            raise SystemExit(f"no real clips in {REAL}: pass --source")
        clips = [("udacity 1280x720", REAL / "udacity_test_video.mp4", udacity_camera()[1]),
                 ("highway 960x540", REAL / "dashcam_highway.mp4", None)]
    return clips


def _loop_rows(args: argparse.Namespace, model: str, long: Path, cal: Calibration | None,
               fps_bar: float) -> list[dict[str, Any]]:
    """``model`` on ``long`` in every loop asked for, with its camera file and calibrating, against model only."""
    rows = []
    for spin in sorted({lp.spin for lp in LOOPS[args.loops]}, reverse=True):
        engine = Engine(model, threads=2, spinning=spin)
        mo = model_only(engine, str(long), min(args.frames, 200), CameraState(engine.card, cal))
        engines = {2: engine}
        for loop in (lp for lp in LOOPS[args.loops] if lp.spin == spin):
            threads = loop.config().engine_threads        # as bsn-run chooses them
            if threads not in engines:
                engines[threads] = Engine(model, threads=threads, spinning=spin)
            for calibration in ([cal, None] if cal is not None else [None]):
                r = profile(engines[threads], long, args.frames, calibration, loop)
                share, tail = r["e2e_fps"] / mo, r["p99_ms"] / r["p50_ms"]
                r.update(model_file=Path(model).name, camera_file=calibration is not None, model_only_fps=mo,
                         e2e_over_model=share, p99_over_p50=tail,
                         passes={"fps": r["e2e_fps"] >= fps_bar, "share": share >= SHARE_BAR,
                                 "tail": tail <= TAIL_BAR})
                rows.append(r)
                print({k: r.get(k) for k in ("model_file", "camera_file", "loop", "e2e_fps", "model_only_fps",
                                             "p50_ms", "p99_ms")}, flush=True)
    return rows


def _live_and_budget(args: argparse.Namespace, model: str, long: Path,
                     cal: Calibration | None) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """``model`` fed ``long`` as a camera delivers it, and its CPU budget, each with and without the camera file."""
    live_rows, budget_rows = [], []
    engine = Engine(model, threads=2)
    for calibration in ([cal, None] if cal is not None else [None]):
        r = live(engine, long, calibration)
        r.update(model_file=Path(model).name, camera_file=calibration is not None)
        live_rows.append(r)
        print({k: r[k] for k in ("camera_file", "frames", "dropped", "camera_fps", "p50_ms", "p99_ms",
                                 "calibrated")}, flush=True)
    for calibration in ([cal, None] if cal is not None else [None]):
        b: dict[str, Any] = dict(cpu_budget(model, long, min(args.frames - 5, 200), calibration))
        b.update(model_file=Path(model).name, camera_file=calibration is not None)
        budget_rows.append(b)
        print(b, flush=True)
    return live_rows, budget_rows


def _markdown(args: argparse.Namespace, rows: list, live_rows: list, budget_rows: list, fps_bar: float,
              vnni: bool) -> list[str]:
    stages = sorted({k for r in rows for k in r["stage_ms"]}, key=lambda k: list(rows[0]["stage_ms"]).index(k)
                    if k in rows[0]["stage_ms"] else 99)
    md = ["# Edge runtime latency profile", "", *median_table(rows, args.repeats, fps_bar),
          f"`bsn-run`'s loop, {args.frames} frames per row (start-up excluded), 2 intra-op threads, CAN on a "
          "virtual bus; model only: the same session on the same frames back to back. Bars: end to end "
          f">= {fps_bar:.0f} frames/s ({'VNNI' if vnni else 'no VNNI'} on this CPU), >= {100 * SHARE_BAR:.0f} % "
          f"of model only, p99 <= {TAIL_BAR:.0f}x p50.", "",
          "| clip | model | camera | loop | end to end frames/s | model only frames/s | ratio | p50 ms | p99 ms | "
          + " | ".join(f"{s} ms" for s in stages) + " | dropped | bars |",
          "|---|---|---|---|---|---|---|---|---|" + "---|" * len(stages) + "---|---|"]
    for r in rows:
        bars = ", ".join(k for k, ok in r["passes"].items() if not ok)
        cam = "file" if r["camera_file"] else "calibrating"
        md.append(f"| {r['clip']} | {r['model_file']} | {cam} | {r['loop']} | "
                  f"{r['e2e_fps']:.1f} | {r['model_only_fps']:.1f} | {100 * r['e2e_over_model']:.0f} % | "
                  f"{r['p50_ms']:.1f} | {r['p99_ms']:.1f} | "
                  + " | ".join(f"{r['stage_ms'].get(s, 0.0):.2f}" for s in stages)
                  + f" | {r['dropped']} | {'pass' if not bars else 'FAIL: ' + bars} |")
    md += ["", "## As a car runs it: each clip delivered like a camera, the default loop", "",
           "| clip | model | camera | camera frames/s | frames processed | dropped | replaced before start | "
           "p50 ms | p99 ms | "
           "wait p50 ms | online calibration at the end |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in live_rows:
        cal = "-" if r["camera_file"] else (("converged" if r["calibrated"] else "still calibrating")
                                            + f" ({r['calibration_pairs'] or 0} pairs used, "
                                              f"{r['calibration_skipped']} frames skipped)")
        md.append(f"| {r['clip']} | {r['model_file']} | {'file' if r['camera_file'] else 'calibrating'} | "
                  f"{r['camera_fps']:.1f} | {r['frames']} | {r['dropped']} | {r['before_start']} | "
                  f"{r['p50_ms']:.1f} | {r['p99_ms']:.1f} | "
                  f"{r['wait_ms']['p50']:.1f} | {cal} |")
    return [*md, "", *budget_table(budget_rows)]


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    if args.repeats < 1:
        p.error(f"--repeats must be at least 1, got {args.repeats}")
    if args.frames < 20:
        p.error(f"--frames must be at least 20, got {args.frames}")
    models = args.model or [str(DEFAULT_MODEL)]
    vnni = "VNNI" in machine()["isa"]
    fps_bar = FPS_BAR_VNNI if vnni else FPS_BAR
    rows: list[dict[str, Any]] = []
    live_rows: list[dict[str, Any]] = []
    budget_rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp_name:
        clips = _clips(args)
        longs = {name: lengthen(video, args.frames, Path(tmp_name)) for name, video, _ in clips}
        for repeat, (name, _, cal) in ((k, c) for k in range(args.repeats) for c in clips):
            for model in models:
                print(f"{name}, {Path(model).name}, repeat {repeat}", flush=True)
                rows += [{**r, "clip": name, "repeat": repeat} for r in _loop_rows(args, model, longs[name], cal,
                                                                                    fps_bar)]
                lv, bd = _live_and_budget(args, model, longs[name], cal)
                live_rows += [{**r, "clip": name, "repeat": repeat} for r in lv]
                budget_rows += [{**r, "clip": name, "repeat": repeat} for r in bd]
    md = _markdown(args, rows, live_rows, budget_rows, fps_bar, vnni)
    return Report({"frames": args.frames, "repeats": args.repeats, "fps_bar": fps_bar, "share_bar": SHARE_BAR,
                   "tail_bar": TAIL_BAR, "rows": rows, "live": live_rows, "cpu_budget": budget_rows}, md, md,
                  name=args.name or class_name("runtime"))


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
