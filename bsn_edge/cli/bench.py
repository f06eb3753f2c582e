"""``bsn-bench``: run the project's benchmarks and write the report.

The benchmarks are the package's (:mod:`bsn_edge.benchmarks`). With a source tree (beside the package,
``--checkout``, ``$BSN_EDGE_CHECKOUT`` or the current folder) every one runs, in it and told where it is; an
installed wheel without one runs those that need nothing of it (:data:`NEEDS_TREE` names the others and what of
the tree each needs) and says which it left out.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from bsn_edge.cli.common import CHECKOUT, CHECKOUT_ENV, REAL_DATA, fail
from bsn_edge.default_model import DEFAULT_MODEL

PROG = "bsn-bench"
# what makes a folder a checkout with everything the benchmarks use (a source distribution has the first only)
MARKS = (Path("configs") / "quick.toml", Path("models") / "README.md")
DEFAULT_STYLES = ("town", "suburb", "highway", "urban")
DEFAULT_SEEDS = 5
NAMES = ("synth", "labels", "train_step", "arch", "quant", "floor", "int8_cpu", "runtime", "accuracy", "install",
         "footprint", "realcam", "realview", "realboxes", "camvid", "realteacher", "vanishing", "adapt", "alive",
         "prune", "calibration", "first_guess", "optimizer", "label_classes", "camera_health", "adapt_real", "ways_out",
         "paced_floor")
# the campaign's own benchmarks: they judge a leg's run folder against held-out sets the campaign makes
# (lab/campaign/judge*.sh run them), so they have nothing to measure outside it
CAMPAIGN_TOOLS = ("bench_cameras", "bench_tradeoff", "bench_campaign")
# what of the source tree a benchmark needs beyond the package (an installed wheel runs the rest)
NEEDS_TREE = {"arch": "configs/quick.toml", "quant": "configs/quick.toml", "accuracy": "configs/quick.toml",
              "adapt": "configs/quick.toml", "install": "the source tree it installs twice",
              "realteacher": "the default's training run (models/default)",
              "alive": "the training runs' weights (models/)", "prune": "the default's training run (models/default)",
              "adapt_real": "the default's training run (models/default)"}
BENCHMARKS = "bsn_edge.benchmarks"
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
    p.add_argument("--checkout", metavar="DIR",
                   help=f"the source tree whose benchmarks/ to run (default: ${CHECKOUT_ENV}, else the checkout the "
                        "package was installed from, else the current folder); an installed wheel runs them against "
                        "itself")
    return p


def _full_install() -> None:
    """What every run needs of the full install, imported before anything runs: a missing one ends the command
    here, said by its guard (:mod:`bsn_edge.cli.full`), not a benchmark's traceback mid-run. The benchmarks
    train and export (torch, onnx); the report plots (matplotlib)."""
    import matplotlib  # noqa: F401
    import onnx  # noqa: F401
    import torch  # noqa: F401


def find_checkout(given: str | None, cwd: Path | None = None) -> Path | None:
    """The source tree with the benchmarks: ``given``, else ``$BSN_EDGE_CHECKOUT``, else the package's own
    checkout, else ``cwd``; None when there is none (an installed wheel); ``FileNotFoundError`` for a tree
    named that is not one."""
    cwd = cwd or Path.cwd()
    named = given or os.environ.get(CHECKOUT_ENV)
    if named:
        root = Path(named).expanduser().resolve()
        if not all((root / m).is_file() for m in MARKS):
            missing = " or ".join(str(m) for m in MARKS if not (root / m).is_file())
            raise FileNotFoundError(f"{named}: no {missing} there: not a bsn-edge checkout")
        return root
    for root in (CHECKOUT, cwd.resolve()):
        if all((root / m).is_file() for m in MARKS):
            return root
    return None


def _py(root: Path | None, *args: str) -> None:
    """``python ARGS`` (the package's modules: ``-m bsn_edge.benchmarks.X``) in the source tree ``root``, told it
    is there (``$BSN_EDGE_CHECKOUT``), or here without one (an installed wheel)."""
    cmd = [sys.executable, *args]
    print("+", " ".join(cmd), flush=True)
    env = None if root is None else {**os.environ, CHECKOUT_ENV: str(root)}
    subprocess.run(cmd, cwd=root, check=True, env=env)


def _prepare_data(root: Path | None, work: Path) -> Path:
    """Labelled clips of every style, made once and reused."""
    data = work / "data"
    # the shipped default's recipe (models/README.md): every style, seeds apart per style
    if not (data / f"{DEFAULT_STYLES[-1]}_{DEFAULT_SEEDS - 1}" / "labels").is_dir():
        for k, style in enumerate(DEFAULT_STYLES):
            for s in range(DEFAULT_SEEDS):
                _py(root, "-m", "bsn_edge.cli.synth", str(data / f"{style}_{s}"), "--frames", "200", "--style", style,
                    "--seed", str(s + 100 * k), "--no-video", "--force")
        _py(root, "-m", "bsn_edge.cli.label", *[str(p) for p in sorted(data.iterdir())])
    return data


def _prepare(root: Path | None, work: Path) -> tuple[Path, Path, Path]:
    """Labelled clips, a trained run and its int8 export, made once and reused."""
    data, run, model = _prepare_data(root, work), work / "run_quick", work / "bsn_int8.onnx"
    from bsn_edge.train.run import Run

    if not Run(run).checkpoint_path.is_file():
        _py(root, "-m", "bsn_edge.cli.train", "--config", "configs/quick.toml", "--data", str(data), "--out", str(run))
    if not model.is_file():
        _py(root, "-m", "bsn_edge.cli.export", "--checkpoint", str(run), "--out", str(model), "--int8", "--int8-frames",
            str(data / "town_0"), "--force")
    return data, run, model


# benchmarks that need nothing but where to write
BY_OUT_ONLY = ("labels", "realcam", "realview", "realboxes", "camvid", "realteacher", "vanishing", "floor",
               "int8_cpu", "install", "footprint", "alive", "prune", "first_guess", "optimizer", "camera_health",
               "ways_out", "paced_floor")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _full_install()
    try:
        root = find_checkout(args.checkout)
    except FileNotFoundError as e:
        return fail(PROG, str(e))
    names = args.only or list(NAMES)
    if root is None:
        left = [n for n in names if n in NEEDS_TREE]
        names = [n for n in names if n not in NEEDS_TREE]
        if left:
            print(f"{PROG}: no source tree (a checkout; --checkout DIR or "
                  f"${CHECKOUT_ENV}): left out " + ", ".join(f"{n} (needs {NEEDS_TREE[n]})" for n in left),
                  file=sys.stderr)
        if not names:
            return fail(PROG, "nothing to run from the installed package alone")
    out, work = str(Path(args.out).resolve()), Path(args.work).resolve()
    t0 = time.perf_counter()
    try:
        for name in names:       # in the order asked (all: the order of NAMES)
            _one(root, name, args, out, work)
        _py(root, "-m", f"{BENCHMARKS}.report", "--results", out)
    except subprocess.CalledProcessError as e:
        return fail(PROG, f"a benchmark failed: {' '.join(map(str, e.cmd))}", 1)
    print(f"{PROG}: done in {time.perf_counter() - t0:.0f} s; report {Path(out) / 'REPORT.md'}")
    return 0


def _one(root: Path | None, name: str, args: argparse.Namespace, out: str, work: Path) -> None:
    if name in BY_OUT_ONLY:
        _py(root, "-m", f"{BENCHMARKS}.bench_{name}", "--out", out)
    elif name == "synth":
        _py(root, "-m", f"{BENCHMARKS}.bench_synth", "--out", out, "--frames", str(args.synth_frames))
    elif name == "train_step":
        _py(root, "-m", f"{BENCHMARKS}.bench_train_step", "--data", str(_prepare_data(root, work)), "--out", out)
    elif name == "quant":
        data, run, _ = _prepare(root, work)
        _py(root, "-m", f"{BENCHMARKS}.bench_quant", "--run", str(run), "--data", str(data), "--calib",
            str(data / "town_0"), "--out", out)
    elif name == "arch":
        data, run, _ = _prepare(root, work)
        _py(root, "-m", f"{BENCHMARKS}.bench_arch", "--out", out, "--runs", f"small-light={run}", "--data", str(data),
            "--train-steps", str(ARCH_STEPS), "--teacher-steps", str(ARCH_STEPS), "--seeds", *map(str, SEEDS),
            "--work", str(work / "arch"))
    elif name == "runtime":
        _runtime(root, out, work)
    elif name == "adapt":
        _adapt(root, out, work)
    elif name == "calibration":
        _calibration(root, out, work)
    elif name == "adapt_real":
        _py(root, "-m", f"{BENCHMARKS}.bench_adapt_real", "--work", str(work / "adapt_real"), "--drive", "0006R0",
            "0001TP", "0016E5", "--out", out)
    elif name == "label_classes":
        campaign = Path("~/.cache/bsn-edge/campaign/data").expanduser()
        data = campaign if campaign.is_dir() else _prepare_data(root, work)
        _py(root, "-m", f"{BENCHMARKS}.bench_label_classes", "--data", str(data), "--out", out)
    elif name == "accuracy":
        _py(root, "-m", f"{BENCHMARKS}.bench_bsn_accuracy", "--out", out, "--work", str(work / "accuracy"), "--seeds",
            *map(str, SEEDS))


def _calibration(root: Path | None, out: str, work: Path) -> None:
    """The real clips that are at hand (no truth) and five synthetic drives (with their truth)."""
    real = [str(REAL_DATA / name) for name in ("udacity_test_video.mp4", "dashcam_highway.mp4",
                                                  "mountain_highway.mp4") if (REAL_DATA / name).is_file()]
    _py(root, "-m", f"{BENCHMARKS}.bench_calibration", *[a for c in real for a in ("--clip", c)], "--cache",
        str(work / "calibration"), "--out", out)


def _runtime(root: Path | None, out: str, work: Path) -> None:
    """The real clips when at hand, else a synthetic one with its camera."""
    source: list[str] = []
    if not (REAL_DATA / "udacity_test_video.mp4").is_file():
        clip = work / "clip" / "video.mp4"
        if not clip.is_file():
            _py(root, "-m", "bsn_edge.cli.synth", str(work / "clip"), "--frames", "300", "--seed", "42", "--force")
        source = ["--source", str(clip)]
    _py(root, "-m", f"{BENCHMARKS}.bench_runtime", "--model", str(DEFAULT_MODEL), *source, "--repeats", "3",
        "--out", out)


def _adapt(root: Path | None, out: str, work: Path) -> None:
    data = _prepare_data(root, work)
    held = work / "adapt_eval"
    for seed in ADAPT_EVAL_SEEDS:
        clip = held / f"{ADAPT_TARGET}_{seed}"
        if not (clip / "labels").is_dir():
            _py(root, "-m", "bsn_edge.cli.synth", str(clip), "--frames", "120", "--style", ADAPT_TARGET, "--seed",
                str(seed), "--no-video", "--force")
            _py(root, "-m", "bsn_edge.cli.label", str(clip))
    _py(root, "-m", f"{BENCHMARKS}.bench_adapt", "--data", str(data), "--eval", str(held), "--source", ADAPT_SOURCE,
        "--target", ADAPT_TARGET, "--work", str(work / "adapt"), "--out", out)


if __name__ == "__main__":
    raise SystemExit(main())
