"""Training health of the project's runs: the share of each network's convolution channels alive.

    python -m bsn_edge.benchmarks.bench_alive [--runs NAME=RUN ...] --out benchmarks/results

A channel is dead when its weights are all (about) zero, or the batch norm after it scales it by about
nothing or has seen it vary by about nothing (``bsn_edge.networks.alive``); the graph still computes it.
Without ``--runs``: the shipped default's run and every run of the campaign folder. For each, D and B
(the student) and its segmentation teacher, in all and per convolution. No timing: it reads weights only.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from bsn_edge.cli.common import CHECKOUT
from bsn_edge.networks.alive import SCALE_EPS, VAR_SHARE, WEIGHT_EPS, Alive, alive_channels
from bsn_edge.train.run import Run

from .common import machine
from .runner import Report, run

DEFAULT_RUNS = CHECKOUT / "models" / "default"
CAMPAIGN = CHECKOUT / "lab" / "campaign"


def default_runs() -> dict[str, Path]:
    """The shipped default's run, then every campaign run that holds a student or a teacher."""
    runs = {"default": DEFAULT_RUNS}
    for p in sorted(CAMPAIGN.iterdir()) if CAMPAIGN.is_dir() else []:
        if (p / "model.pt").is_file() or (p / "teacher" / "teacher.pt").is_file():
            runs[p.name] = p
    return runs


def networks(path: Path) -> dict[str, Alive]:
    """{"student": ..., "teacher": ...} for the run at ``path`` (each only when the run holds it)."""
    r = Run(path)
    out = {}
    if (path / "model.pt").is_file():
        out["student"] = alive_channels(r.load_model()[0])
    teacher = r.load_teacher()
    if teacher is not None:
        out["teacher"] = alive_channels(teacher)
    return out


def measure(args: argparse.Namespace, _parser: argparse.ArgumentParser) -> Report:
    runs = dict(spec.split("=", 1) for spec in args.runs) if args.runs else default_runs()
    result: dict[str, Any] = {"machine": machine(), "runs": {}}
    md = ["# Alive channels", "", "The share of each network's convolution output channels that carry anything: "
          f"some weight of at least {WEIGHT_EPS:g}, and where a batch norm follows, its scale over {SCALE_EPS:g} "
          f"and its running variance at least {VAR_SHARE:g} of its epsilon (`bsn_edge.networks.alive`).", "",
          "| run | student alive | teacher alive |", "|---|---|---|"]
    per_layer: list[str] = []
    for name, path in runs.items():
        nets = networks(Path(path))
        result["runs"][name] = {"path": str(path), **{k: a.to_dict(per_layer=True) for k, a in nets.items()}}
        cells = [f"{100 * nets[k].share:.1f} % ({nets[k].alive:,} of {nets[k].channels:,})" if k in nets else "-"
                 for k in ("student", "teacher")]
        md.append(f"| {name} | {cells[0]} | {cells[1]} |")
        for kind, a in nets.items():
            per_layer += ["", f"## {name}: {kind}", "", a.line(), "", "| convolution | channels | alive |",
                          "|---|---|---|"]
            per_layer += [f"| `{la.name}` | {la.channels} | {la.alive} ({100 * la.share:.0f} %) |" for la in a.layers]
    return Report(result, md + per_layer)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="bench_alive", description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", nargs="*", metavar="NAME=RUN",
                   help="runs to read (default: the default and the campaign's)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="alive")
    return run(measure, p, argv)


if __name__ == "__main__":
    raise SystemExit(main())
