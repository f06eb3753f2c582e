"""What every benchmark shares: the machine description and the result writers."""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


def machine() -> dict[str, Any]:
    """The machine a result was measured on."""
    cpu = platform.processor() or platform.machine()
    flags: set[str] = set()
    try:
        info: dict[str, str] = {}
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            info.setdefault(key.strip(), value.strip())   # the first processor's
        cpu = info.get("model name", cpu)
        flags = set(info.get("flags", "").split())
    except OSError:
        pass
    # machines of one name differ in what int8 runs on (the same "AMD EPYC" came with and without VNNI)
    isa = [n for n, f in (("AVX-512", "avx512f"), ("VNNI", "avx512_vnni"), ("AVX-VNNI", "avx_vnni"), ("AVX2", "avx2"),
                          ("AVX512-BF16", "avx512_bf16"), ("AMX", "amx_tile"))
           if f in flags]
    return {"cpu": cpu, "isa": isa, "cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform()}


def cpu_named(m: dict[str, Any]) -> str:
    """A machine record's CPU and the instruction sets it has that the results depend on."""
    return m["cpu"] + (f" ({', '.join(m['isa'])})" if m["isa"] else "")


def named(specs: list[str]) -> dict[str, str]:
    """``[NAME=]PATH`` arguments (``--model``, ``--teacher``) as ``{name: path}`` in their order; a path
    given without a name is named by its file's stem (and its ``@THRESHOLD``, :func:`operating_point`).
    ValueError when two get the same name, which would report one model's figures under the other's."""
    out: dict[str, str] = {}
    for spec in specs:
        name, _, path = spec.rpartition("=")
        if not name:
            file, threshold = operating_point(path)
            name = Path(file).stem + ("" if threshold is None else f"@{threshold:g}")
        if name in out:
            raise ValueError(f"two models are named {name!r} ({out[name]} and {path}): name them, NAME=PATH")
        out[name] = path
    return out


def operating_point(spec: str) -> tuple[str, float | None]:
    """``MODEL.onnx[@THRESHOLD]`` as ``(path, threshold)``: a model read at another decision threshold
    than its card's (``None``: the card's)."""
    path, at, t = spec.rpartition("@")
    if not at:
        return spec, None
    try:
        return path, float(t)
    except ValueError:
        return spec, None       # an @ that is part of the file's name


def load_engine(spec: str) -> Any:
    """The model of ``MODEL.onnx[@THRESHOLD]`` loaded as the runtime loads it, deciding at that threshold."""
    from bsn_edge.runtime.engine import Engine

    path, threshold = operating_point(spec)
    return Engine(path, threshold=threshold)


def class_name(base: str) -> str:
    """A per-machine report's name for this CPU's int8 class: ``base`` with VNNI, ``base_avx2`` on an x86
    CPU without it, ``base_<arch>`` elsewhere (so one class's results never overwrite another's)."""
    isa = machine()["isa"]
    if "VNNI" in isa or "AVX-VNNI" in isa:
        return base
    return f"{base}_avx2" if "AVX2" in isa else f"{base}_{platform.machine().lower()}"


def time_calls(fn: Callable[[int], Any], n: int, warmup: int = 3) -> list[float]:
    """Seconds per call of ``fn(i)`` for ``i`` in ``range(n)``, after ``warmup`` calls."""
    for i in range(warmup):
        fn(i)
    out = []
    for i in range(n):
        t0 = time.perf_counter()
        fn(i)
        out.append(time.perf_counter() - t0)
    return out


def summary(seconds: list[float]) -> dict[str, float]:
    """Median, p95 and rate of a list of per-call times."""
    s = sorted(seconds)
    med = statistics.median(s)
    return {"median_ms": 1e3 * med, "p95_ms": 1e3 * s[min(len(s) - 1, int(0.95 * len(s)))],
            "per_second": 1.0 / med, "n": len(s)}


def portable(text: str) -> str:
    """``text`` with this machine's paths made readable anywhere: the working folder's own prefix
    dropped (paths relative to the checkout), what lies beside it written from it (``../shared/...``,
    the real data) and the home folder written ``~``."""
    cwd, home = os.getcwd().rstrip("/"), os.path.expanduser("~").rstrip("/")
    if cwd:
        text = text.replace(cwd + "/", "")
    if home:
        text = text.replace(home + "/", "~/")
    beside = os.path.dirname(cwd) if cwd else ""
    return text.replace(beside + "/", "../") if beside not in ("", "/") else text


def models_parser(description: str, name: str) -> argparse.ArgumentParser:
    """The arguments every benchmark of exported models takes: ``--out``, ``--model [NAME=]MODEL.onnx``
    (repeatable, scored side by side) and ``--name`` (the report's, default ``name``)."""
    p = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--model", action="append", metavar="[NAME=]MODEL.onnx[@THRESHOLD]",
                   help="exported models, scored side by side (default: the shipped one), each at its card's "
                        "threshold or at the one after @ (a model's operating points side by side)")
    p.add_argument("--name", default=name, help="the report's name in --out")
    return p


def engines(p: argparse.ArgumentParser, specs: list[str] | None) -> dict[str, Any]:
    """The models ``--model`` names (the shipped one when none), loaded as the runtime loads them; a
    usage error through ``p`` for two of one name or a model that does not load."""
    from bsn_edge.default_model import DEFAULT_MODEL

    try:
        return {name: load_engine(spec) for name, spec in named(specs or [str(DEFAULT_MODEL)]).items()}
    except ValueError as e:
        p.error(str(e))


def write_result(out_dir: str | Path, name: str, result: dict[str, Any], markdown: str) -> Path:
    """Write ``<name>.json`` and ``<name>.md`` into ``out_dir``, this machine's paths in them made
    portable (:func:`portable`); returns the JSON path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": name, "measured_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "machine": machine(), **result}
    (out / f"{name}.json").write_text(portable(json.dumps(result, indent=2)) + "\n")
    markdown = portable(markdown)
    m = result["machine"]
    (out / f"{name}.md").write_text(markdown.rstrip() + f"\n\nMeasured on {cpu_named(m)}, "
                                    f"{m['cores']} cores, Python {m['python']}.\n")
    return out / f"{name}.json"


def records(steps: int, n: int = 10) -> list[str]:
    """``bsn-train`` settings for a run of ``steps`` that records its validation ``n`` times and saves
    its state with each record: the curve has its points, and a stopped run goes on from the last one."""
    every = max(1, steps // n)
    return [f"train.eval_every={every}", f"train.checkpoint_every={every}"]


def train_run(data: Path, out: Path, sets: list[str], stop_after: float | None = None) -> Path:
    """``bsn-train --data data --out out --set ...`` in this process; a finished run is reused, one
    stopped part-way goes on from its last saved state (``--resume``). ``stop_after`` (minutes) ends
    this piece with its state saved, the run then not ``finished()`` (bsn-train's ``--stop-after``)."""
    from bsn_edge.cli import train as train_cli
    from bsn_edge.train.run import Run

    run = Run(out)
    if run.finished():
        return out
    # progress bars only where someone watches; a log gets one line when a run starts and one when it ends
    argv = ["--data", str(data), "--out", str(out), *(() if sys.stderr.isatty() else ("--quiet",))]
    if run.state_path.is_file() or run.teacher_state_path.is_file():
        print(f"{out}: going on from its saved training state", flush=True)
        argv.append("--resume")
    else:
        print(f"{out}: training", flush=True)
    for s in sets:
        argv += ["--set", s]
    if stop_after is not None:
        argv += ["--stop-after", f"{stop_after:g}"]
    t0 = time.perf_counter()
    if train_cli.main(argv):
        raise RuntimeError(f"training {out} failed")
    print(f"{out}: trained in {time.perf_counter() - t0:.0f} s", flush=True)
    return out


def eval_run(run: Path, data: Path, out: Path, *extra: str) -> dict[str, Any]:
    """``bsn-eval --run run --data data --out out ...`` in this process; returns the report."""
    from bsn_edge.cli import eval as eval_cli

    if eval_cli.main(["--run", str(run), "--data", str(data), "--out", str(out), *extra]):
        raise RuntimeError(f"evaluating {run} failed")
    return json.loads(out.read_text())
