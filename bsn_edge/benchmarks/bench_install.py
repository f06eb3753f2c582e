"""What the car carries: the base install's size, bsn-run's import time and memory, against the full install.

    python -m bsn_edge.benchmarks.bench_install --out benchmarks/results [--full-python .venv/bin/python]

Makes a fresh virtual environment with the base install only (``pip install .``: numpy, OpenCV,
onnxruntime, python-can, cantools, pyserial, tqdm), checks that ``import torch`` fails there, runs
``bsn-run`` on a synthetic clip with the shipped model (overlay, JSON lines and CAN log written),
and measures, beside the full install (``--full-python``, the development environment):

- install size: the environment's site-packages, MB;
- import time of what ``bsn-run`` loads before its first frame (``RUN_MODULES``: the entry module,
  which imports only the standard library so that signals are watched first, then the runtime;
  median of 7 fresh interpreters, interpreter start-up
  subtracted), against the base dependencies alone and against the old path (torch, onnx and the
  quantization tools loaded with it, as before the core was split);
- peak RSS of ``bsn-run`` after its first frame (``--max-frames 1``), MB.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bsn_edge.cli.common import CHECKOUT
from bsn_edge.default_model import DEFAULT_MODEL

from .runner import Report, run

BASE_MODULES = "numpy, cv2, onnxruntime, can, cantools, serial, tqdm"
OLD_PATH = "torch, onnx, onnxruntime.quantization"
RUN_MODULES = "bsn_edge.cli.run, bsn_edge.runtime, bsn_edge.calibration.camera_file, tqdm"
GOAL_IMPORT = 1.15       # bsn-run's import within 15 % of the base dependencies alone
GOAL_RSS_MB = 150.0
MODEL = DEFAULT_MODEL


def site_mb(python: str) -> float:
    code = "import site, json; print(json.dumps(site.getsitepackages()))"
    dirs = json.loads(subprocess.run([python, "-c", code], capture_output=True, text=True, check=True).stdout)
    total = sum(f.stat().st_size for d in dirs for f in Path(d).rglob("*") if f.is_file() and not f.is_symlink())
    return total / 1e6


def import_s(python: str, modules: str, repeats: int = 7) -> float:
    """Median seconds to import ``modules`` in a fresh interpreter, start-up subtracted."""
    def once(code: str) -> float:
        t = time.perf_counter()
        subprocess.run([python, "-c", code], check=True, cwd="/")
        return time.perf_counter() - t

    empty = statistics.median(once("pass") for _ in range(repeats))
    return statistics.median(once(f"import {modules}") for _ in range(repeats)) - empty


def run_rss_mb(python: str, clip: Path, summary: Path) -> float:
    """Peak RSS of bsn-run after one frame, MB (its own process); its summary written to ``summary`` (a new file:
    bsn-run overwrites nothing)."""
    code = ("import resource, sys; from bsn_edge.cli import run; "
            f"rc = run.main(['--model', {str(MODEL)!r}, '--source', {str(clip)!r}, '--max-frames', '1', "
            f"'--summary', {str(summary)!r}]); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024); sys.exit(rc)")
    res = subprocess.run([python, "-c", code], capture_output=True, text=True, check=True, cwd="/")
    return float(res.stdout.strip().splitlines()[-1])


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--full-python", default=sys.executable, help="python of the full install (default: this one)")
    p.add_argument("--name", default="install", help="the report's name in --out")
    return p


def _base_install(tmp: Path) -> tuple[str, float, bool]:
    """A fresh venv with ``pip install .`` only: its python, the install's seconds, whether torch is missing."""
    venv = tmp / "base"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    base_py = str(venv / "bin" / "python")
    subprocess.run([base_py, "-m", "pip", "install", "--quiet", str(CHECKOUT)], check=True)
    install_s = time.perf_counter() - t0
    torch_missing = subprocess.run([base_py, "-c", "import torch"], capture_output=True).returncode != 0
    return base_py, install_s, torch_missing


def _markdown(res: dict[str, Any]) -> list[str]:
    b, f = res["rows"]["base"], res["rows"]["full"]
    ran = res["bsn_run_in_base"]
    return ["# The car's footprint: base install vs full install", "",
            "A fresh virtual environment with `pip install .` only, beside the development environment "
            "(`.[full,dev]`), measured in one run.", "",
            "| | base install | full install |", "|---|---|---|",
            f"| site-packages, MB | {b['site_packages_mb']:.0f} | {f['site_packages_mb']:.0f} |",
            f"| import `bsn-run`, s | {b['import_bsn_run_s']:.2f} | {f['import_bsn_run_s']:.2f} "
            f"(old path with torch, onnx, quantization: {f['import_old_path_s']:.2f}) |",
            f"| import numpy, OpenCV, onnxruntime, python-can, cantools, pyserial, tqdm alone, s | "
            f"{b['import_base_deps_s']:.2f} | {f['import_base_deps_s']:.2f} |",
            f"| peak RSS of `bsn-run` after its first frame, MB | {b['rss_after_first_frame_mb']:.0f} | "
            f"{f['rss_after_first_frame_mb']:.0f} |", "",
            f"In the base install `import torch` {'fails' if res['torch_missing_in_base'] else 'WORKS (it must not)'}; "
            f"`bsn-run` on a 30-frame clip exited {ran['rc']} and wrote "
            f"{', '.join(k for k, v in ran['written'].items() if v) or 'nothing'}. bsn-run's import is "
            f"{res['import_ratio']:.2f}x the base dependencies' (goal <= {GOAL_IMPORT}); RSS goal < "
            f"{GOAL_RSS_MB:.0f} MB ({'met' if res['passes'] else 'NOT met'})."]


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        base_py, install_s, torch_missing = _base_install(tmp)
        clip = tmp / "clip"
        subprocess.run([str(Path(base_py).parent / "bsn-synth"), str(clip), "--frames", "30", "--seed", "3"],
                       check=True, capture_output=True)
        outs = tmp / "run"
        outs.mkdir()
        rc = subprocess.run([str(Path(base_py).parent / "bsn-run"), "--model", str(MODEL), "--source",
                             str(clip / "video.mp4"), "--overlay", str(outs / "overlay.mp4"), "--log",
                             str(outs / "alerts.jsonl"), "--can-log", str(outs / "alerts.log")],
                            capture_output=True, text=True)
        written = {n: (outs / n).is_file() and (outs / n).stat().st_size > 0
                   for n in ("overlay.mp4", "alerts.jsonl", "alerts.log")}
        rows = {}
        for name, py in (("base", base_py), ("full", args.full_python)):
            rows[name] = {
                "site_packages_mb": round(site_mb(py), 1),
                "import_bsn_run_s": round(import_s(py, RUN_MODULES), 3),
                "import_base_deps_s": round(import_s(py, BASE_MODULES), 3),
                "rss_after_first_frame_mb": round(run_rss_mb(py, clip / "video.mp4", outs / f"rss_{name}.json"), 1),
            }
        rows["full"]["import_old_path_s"] = round(import_s(args.full_python, f"{OLD_PATH}, {RUN_MODULES}"), 3)
    b = rows["base"]
    res: dict[str, Any] = {"rows": rows, "base_install_s": round(install_s, 1), "torch_missing_in_base": torch_missing,
           "bsn_run_in_base": {"rc": rc.returncode, "written": written},
           "import_ratio": b["import_bsn_run_s"] / b["import_base_deps_s"],
           "goal_import_ratio": GOAL_IMPORT, "goal_rss_mb": GOAL_RSS_MB}
    res["passes"] = (torch_missing and rc.returncode == 0 and all(written.values())
                     and res["import_ratio"] <= GOAL_IMPORT and b["rss_after_first_frame_mb"] < GOAL_RSS_MB)
    md = _markdown(res)
    return Report(res, md, md)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
