"""``bsn-bench``: run the project's benchmarks (from a checkout) and write the report."""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

from bsn_edge.cli.common import CHECKOUT, REAL_DATA, fail
from bsn_edge.default_model import DEFAULT_MODEL

PROG = "bsn-bench"
DEFAULT_STYLES = ("town", "suburb", "highway", "urban")
DEFAULT_SEEDS = 5
NAMES = ("synth", "labels", "train_step", "arch", "quant", "floor", "int8_cpu", "runtime", "accuracy", "footprint",
         "realcam", "realview", "realboxes", "camvid", "realteacher", "vanishing", "adapt", "alive", "prune")
ADAPT_SOURCE, ADAPT_TARGET = "suburb", "urban"
ADAPT_EVAL_SEEDS = (1300, 1301)   # held-out target clips: seeds no training clip has
SEEDS = (0, 1, 2)                 # training seeds of the paper's tables
ARCH_STEPS = 3000                 # Table 3's budget per run (and its teacher's), batch 8 at 128x256


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Run bsn-edge's benchmarks on this machine and write benchmarks/results/<name>.json and .md "
                    "plus REPORT.md with plots. Data and a quick.toml-trained run are made in --work when missing "
                    "(about 25 minutes on 2 cores the first time). 'arch' and 'accuracy' are the paper's Tables 3 "
                    "and 2 with three seeds at 128x256, each run long enough to flatten: many CPU-hours, so every "
                    "finished run is kept in a ledger beside the results and a later 'bsn-bench --only accuracy' "
                    "(on any machine) trains only what is missing. 'adapt' trains a one-style model and adapts it "
                    "with bsn-adapt (about 75 minutes).")
    p.add_argument("--only", nargs="*", choices=NAMES, default=None, help="run only these (default: all)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--work", default="benchmarks/scratch", help="clips, runs and models made for the benchmarks")
    p.add_argument("--synth-frames", type=int, default=100, metavar="N",
                   help="frames per style timed by 'synth' (default 100; fewer only to check the plumbing)")
    return p


def _py(*args: str) -> None:
    cmd = [sys.executable, *args]
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=CHECKOUT, check=True)


def _prepare_data(work: Path) -> Path:
    """Labelled clips of every style, made once and reused."""
    data = work / "data"
    # the shipped default's recipe (models/README.md): every style, seeds apart per style
    if not (data / f"{DEFAULT_STYLES[-1]}_{DEFAULT_SEEDS - 1}" / "labels").is_dir():
        for k, style in enumerate(DEFAULT_STYLES):
            for s in range(DEFAULT_SEEDS):
                _py("-m", "bsn_edge.cli.synth", str(data / f"{style}_{s}"), "--frames", "200", "--style", style,
                    "--seed", str(s + 100 * k), "--no-video", "--force")
        _py("-m", "bsn_edge.cli.label", *[str(p) for p in sorted(data.iterdir())])
    return data


def _prepare(work: Path) -> tuple[Path, Path, Path]:
    """Labelled clips, a trained run and its int8 export, made once and reused."""
    data, run, model = _prepare_data(work), work / "run_quick", work / "bsn_int8.onnx"
    from bsn_edge.train.run import Run

    if not Run(run).checkpoint_path.is_file():
        _py("-m", "bsn_edge.cli.train", "--config", "configs/quick.toml", "--data", str(data), "--out", str(run))
    if not model.is_file():
        _py("-m", "bsn_edge.cli.export", "--checkpoint", str(run), "--out", str(model), "--int8", "--int8-frames",
            str(data / "town_0"), "--force")
    return data, run, model


# benchmarks that need nothing but where to write
BY_OUT_ONLY = {"labels": "benchmarks.bench_labels", "realcam": "benchmarks.bench_realcam",
               "realview": "benchmarks.bench_realview", "realboxes": "benchmarks.bench_realboxes",
               "camvid": "benchmarks.bench_camvid", "realteacher": "benchmarks.bench_realteacher",
               "vanishing": "benchmarks.bench_vanishing",
               "floor": "benchmarks.bench_floor", "int8_cpu": "benchmarks.bench_int8_cpu",
               "footprint": "benchmarks.bench_footprint", "alive": "benchmarks.bench_alive",
               "prune": "benchmarks.bench_prune"}


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not (CHECKOUT / "benchmarks" / "report.py").is_file():
        return fail(PROG, f"benchmarks/ not found beside the package ({CHECKOUT}); bsn-bench runs from a checkout")
    names = args.only or list(NAMES)
    out, work = str(Path(args.out).resolve()), Path(args.work).resolve()
    t0 = time.perf_counter()
    try:
        for name in names:       # in the order asked (all: the order of NAMES)
            _one(name, args, out, work)
        _py("-m", "benchmarks.report", "--results", out)
    except subprocess.CalledProcessError as e:
        return fail(PROG, f"a benchmark failed: {' '.join(map(str, e.cmd))}", 1)
    print(f"{PROG}: done in {time.perf_counter() - t0:.0f} s; report {Path(out) / 'REPORT.md'}")
    return 0


def _one(name: str, args: argparse.Namespace, out: str, work: Path) -> None:
    if name in BY_OUT_ONLY:
        _py("-m", BY_OUT_ONLY[name], "--out", out)
    elif name == "synth":
        _py("-m", "benchmarks.bench_synth", "--out", out, "--frames", str(args.synth_frames))
    elif name == "train_step":
        _py("-m", "benchmarks.bench_train_step", "--data", str(_prepare_data(work)), "--out", out)
    elif name == "quant":
        data, run, _ = _prepare(work)
        _py("-m", "benchmarks.bench_quant", "--run", str(run), "--data", str(data), "--calib", str(data / "town_0"),
            "--out", out)
    elif name == "arch":
        data, run, _ = _prepare(work)
        _py("-m", "benchmarks.bench_arch", "--out", out, "--runs", f"small-light={run}", "--data", str(data),
            "--train-steps", str(ARCH_STEPS), "--teacher-steps", str(ARCH_STEPS), "--seeds", *map(str, SEEDS),
            "--work", str(work / "arch"))
    elif name == "runtime":
        _runtime(out, work)
    elif name == "adapt":
        _adapt(out, work)
    elif name == "accuracy":
        _py("-m", "benchmarks.bench_bsn_accuracy", "--out", out, "--work", str(work / "accuracy"), "--seeds",
            *map(str, SEEDS))


def _runtime(out: str, work: Path) -> None:
    """The real clips when at hand, else a synthetic one with its camera."""
    source: list[str] = []
    if not (REAL_DATA / "udacity_test_video.mp4").is_file():
        clip = work / "clip" / "video.mp4"
        if not clip.is_file():
            _py("-m", "bsn_edge.cli.synth", str(work / "clip"), "--frames", "300", "--seed", "42", "--force")
        source = ["--source", str(clip)]
    _py("-m", "benchmarks.bench_runtime", "--model", str(DEFAULT_MODEL), *source, "--repeats", "3", "--out", out)


def _adapt(out: str, work: Path) -> None:
    data = _prepare_data(work)
    held = work / "adapt_eval"
    for seed in ADAPT_EVAL_SEEDS:
        clip = held / f"{ADAPT_TARGET}_{seed}"
        if not (clip / "labels").is_dir():
            _py("-m", "bsn_edge.cli.synth", str(clip), "--frames", "120", "--style", ADAPT_TARGET, "--seed", str(seed),
                "--no-video", "--force")
            _py("-m", "bsn_edge.cli.label", str(clip))
    _py("-m", "benchmarks.bench_adapt", "--data", str(data), "--eval", str(held), "--source", ADAPT_SOURCE,
        "--target", ADAPT_TARGET, "--work", str(work / "adapt"), "--out", out)


if __name__ == "__main__":
    raise SystemExit(main())
