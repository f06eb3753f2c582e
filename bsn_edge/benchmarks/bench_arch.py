"""Architectures (the paper's Table 3): parameters, GMACs, CPU frames/s and IoU.

    python -m bsn_edge.benchmarks.bench_arch --out benchmarks/results --data CLIPS [--train-steps 300]
                                    [--runs small-light=RUN ...]

GMACs are counted by ``torch.utils.flop_counter`` at 256x512 for the whole fused model (D and B).
Frames/s: the fused fp32 ONNX model in onnxruntime, 2 intra-op threads, median of ``--repeats``
runs after warm-up, all in one run of this script.

IoU: with ``--train-steps``, every architecture is trained on ``--data`` with one budget (steps,
batch 8, ``--train-size``, one shared teacher, the 60/20/20 clip split of ``configs/quick.toml``)
once per ``--seeds`` and evaluated inside V on the held-out clips, so the column compares
architectures, not budgets: mean +- std over the seeds, with each run's validation curve (flat: its
last fifth gained under 0.01), and which differences between architectures exceed the seeds' spread.
Every finished run goes into ``bsn_arch_ledger.json`` in ``--out``
(:mod:`bsn_edge.benchmarks.ledger`): the command can be stopped and run again, on any machine, and trains
only what is missing, a run stopped part-way going on from its last tenth. ``--report NAME`` writes
``NAME.md`` and ``NAME_ledger.json`` instead, e.g. a table of two architectures (``--only``) that
leaves the whole table as it is. The report has a row for every architecture of ``--only`` and every
one its ledger holds, so a table trained one run per sitting (``--only small --seeds 0``, then
``--only unet --seeds 0`` ...) shows every run finished so far. ``--stop-after MINUTES`` ends a sitting
with the run in progress saved at the step it reached (the same command goes on from there), so a
sitting of known length loses no training. A sitting on a CPU whose ``train.precision=auto`` picks
another arithmetic than the ledger's runs were trained in (fp32 where they are bf16) is refused before
it trains, unless ``--mixed-arithmetic``. ``--runs`` adds the IoU of runs trained elsewhere (e.g. the
shipped model's).
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import torch

from bsn_edge.card import UNRECORDED
from bsn_edge.cli.common import parse_size
from bsn_edge.train.config import load_config
from bsn_edge.train.device import autocast_dtype, precision_name
from bsn_edge.train.run import Run

from .arch_speed import earlier_timing, measure_arch
from .bench_campaign import run_curve
from .common import cpu_named, eval_run, machine, records, train_run
from .ledger import Ledger, exceeds_spread, fmt, mean_std
from .runner import RefusedError, Report, run

ARCHS = ("unet", "small", "small-light", "shared-light", "medium", "large")


def train_uniform(name: str, data: Path, work: Path, steps: int, size: tuple[int, int], teacher: Path | None,
                  seed: int = 0, stop_after: float | None = None) -> Path:
    """Train ``name`` on ``data`` with the benchmark's budget into its ``run_folder`` (reused if done),
    validation IoU every tenth of the steps; ``stop_after`` (minutes) as for ``train_run``."""
    sets = [f"model.name={name}", f"data.size=[{size[0]}, {size[1]}]", "data.val_fraction=0.2",
            "data.test_fraction=0.2", f"train.steps={steps}", "train.batch_size=8", *records(steps),
            f"train.seed={seed}", "train.eval_frames=128"]
    if teacher is not None:
        sets.append(f"teacher.checkpoint={teacher}")
    return train_run(data, run_folder(work, name, seed), sets, stop_after)


def run_folder(work: Path, name: str, seed: int) -> Path:
    """Where ``train_uniform`` trains ``name`` with ``seed``: ``work/name``, ``work/seedN/name`` after seed 0."""
    return (work / name) if seed == 0 else (work / f"seed{seed}" / name)


def run_budget(run: Path) -> str:
    """How a run was trained, from its resolved config."""
    cfg = json.loads((run / "config.json").read_text())
    h, w = cfg["data"]["size"]
    return f"trained {cfg['train']['steps']} steps of batch {cfg['train']['batch_size']} at {h}x{w}"


def held_out_iou(run: Path, data: Path, report: Path) -> float:
    """IoU inside V of ``run`` on its held-out clips of ``data``, at its training size."""
    return round(eval_run(run, data, report, "--no-baselines")["overall"]["BSN"]["iou"], 4)


def train_seeds(args: argparse.Namespace, ledger: Ledger, tmp: Path) -> tuple[Path, Path | None]:
    """Train every (seed, architecture) missing from ``ledger``, seeds outermost; returns the teacher, and
    the run folder left part-way when ``args.stop_after`` ended the sitting first (else None)."""
    data, work = Path(args.data), Path(args.work)
    teacher = Path(args.teacher) if args.teacher else work / "teacher" / "teacher"
    deadline = None if args.stop_after is None else time.monotonic() + 60.0 * args.stop_after

    def minutes_left() -> float | None:
        return None if deadline is None else (deadline - time.monotonic()) / 60.0

    def stopped(run: Path) -> bool:
        return deadline is not None and not Run(run).finished()

    if not args.teacher:
        train_run(data, teacher.parent, [f"data.size=[{args.train_size[0]}, {args.train_size[1]}]",
                                         "data.val_fraction=0.2", "data.test_fraction=0.2", "train.steps=1",
                                         "train.checkpoint_every=1", f"teacher.steps={args.teacher_steps}",
                                         f"teacher.eval_every={max(1, args.teacher_steps // 10)}"])
    for key in runs_left(args, ledger):
        name, seed = split_key(key)
        left = minutes_left()
        if left is not None and left <= 0:
            return teacher, run_folder(work, name, seed)
        run = train_uniform(name, data, work, args.train_steps, args.train_size, teacher, seed, left)
        if stopped(run):
            return teacher, run
        m = machine()
        ledger.put(key, {"iou": held_out_iou(run, data, tmp / f"{name}_{seed}.json"), "curve": run_curve(run),
                         "finished_on": {"cpu": m["cpu"], "isa": m["isa"]}})
        if not args.keep_runs:
            shutil.rmtree(run, ignore_errors=True)
    return teacher, None


def runs_left(args: argparse.Namespace, ledger: Ledger) -> list[str]:
    """The ledger keys of ``--seeds`` x ``--only`` not in ``ledger`` yet, seeds outermost (the order they train in)."""
    return [k for k in (run_key(name, seed) for seed in args.seeds for name in args.only) if k not in ledger]


def run_key(name: str, seed: int) -> str:
    """The ledger's key of one architecture's run with one seed; ``split_key`` reads it back."""
    return f"{name}/seed{seed}"


def split_key(key: str) -> tuple[str, int]:
    """Architecture and seed of a ledger key written by ``run_key``."""
    name, seed = key.split("/seed")
    return name, int(seed)


def trained_in(records: Iterable[dict]) -> list[str]:
    """The arithmetic the ledger ``records`` were trained in, sorted (``UNRECORDED`` for a run from
    before the history named it)."""
    return sorted({p for r in records for p in r["curve"].get("precision", [UNRECORDED])})


def arithmetic_clash(ledger: Ledger, here: str) -> str | None:
    """Why training with this CPU's arithmetic ``here`` would mix arithmetic into ``ledger``'s table
    (its runs were all trained in another), or None when it would not."""
    before = [p for p in trained_in(ledger.runs.values()) if p != UNRECORDED]
    if not before or here in before:
        return None
    return (f"this CPU trains in {here} (train.precision=auto; bf16 needs AMX or AVX-512 BF16) and the "
            f"ledger's runs were trained in {' and '.join(before)}: a run trained here would mix arithmetic "
            "in one table. Train on a CPU with the ledger's arithmetic, or pass --mixed-arithmetic to train "
            "here anyway")


def table_rows(only: list[str], ledger: Ledger | None) -> list[str]:
    """The architectures a report has a row for, in the table's order: those asked for and every one its
    ledger holds (a table trained one run per sitting, ``--only`` and ``--seeds``, shows every run)."""
    held = {split_key(key)[0] for key in ledger.runs} if ledger is not None else set()
    return [a for a in ARCHS if a in only or a in held]


def finished_on(ledger: Ledger, names: list[str]) -> list[str]:
    """One line per machine that finished runs of ``names`` (the sitting that finished a run may differ
    from the earlier ones), its runs listed; runs put in the ledger before it named the machine last."""
    by: dict[str, list[str]] = {}
    for key in sorted(ledger.runs):
        name, seed = split_key(key)
        if name in names:
            m = ledger.runs[key].get("finished_on")
            by.setdefault(cpu_named(m) if m else "", []).append(f"`{name}` seed {seed}")
    return [f"- {cpu or 'not recorded'}: {', '.join(keys)}" for cpu, keys in sorted(by.items(), key=lambda i: not i[0])]


def differences(rows: list[dict]) -> list[dict]:
    """Every pair of rows with seeds, higher mean IoU first: the difference of the means and whether
    it exceeds the seeds' spread (None while a side has one seed)."""
    seeded = [(r, mean_std(r["iou_seeds"])[0]) for r in rows if r.get("iou_seeds")]
    out = []
    for i, a in enumerate(seeded):
        for b in seeded[i + 1:]:
            (hi, m_hi), (lo, m_lo) = (a, b) if a[1] >= b[1] else (b, a)
            out.append({"higher": hi["model"], "lower": lo["model"], "difference": round(m_hi - m_lo, 4),
                        "beyond_spread": exceeds_spread(hi["iou_seeds"], lo["iou_seeds"])})
    return out


def plot_curves(ledger: Ledger, names: list[str], path: Path) -> bool:
    """Every run's validation IoU over its steps, one colour per architecture, into ``path``; False
    (nothing drawn) when the ledger has no curve of ``names``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [(k, r["curve"]) for k, r in sorted(ledger.runs.items()) if r.get("curve", {}).get("steps")
            and split_key(k)[0] in names]
    if not runs:
        return False
    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    colours = {n: f"C{i}" for i, n in enumerate(names)}
    labelled: set[str] = set()
    for key, c in runs:
        name = split_key(key)[0]
        ax.plot(c["steps"], c["val_iou"], color=colours[name], alpha=0.8, marker=".",
                label=None if name in labelled else name)
        labelled.add(name)
    ax.set_xlabel("step")
    ax.set_ylabel("validation IoU")
    ax.set_title("validation IoU over training, every seed")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--repeats", type=int, default=30)
    p.add_argument("--runs", nargs="*", default=[], metavar="NAME=RUN", help="trained runs for the IoU column")
    p.add_argument("--data", default=None, help="labelled clips: training (--train-steps) and held-out IoU")
    p.add_argument("--train-steps", type=int, default=0, help="train every architecture this many steps (0: no)")
    p.add_argument("--train-size", type=parse_size, default=(128, 256), metavar="HxW", help="training size")
    p.add_argument("--seeds", type=int, nargs="+", default=[0], help="training seeds (default 0; the table: 0 1 2)")
    p.add_argument("--teacher", default=None, help="a trained teacher's folder (default: one is trained first)")
    p.add_argument("--teacher-steps", type=int, default=300, help="steps of the teacher trained first")
    p.add_argument("--work", default="benchmarks/scratch/arch", help="runs trained by --train-steps are kept here")
    p.add_argument("--keep-runs", action="store_true", help="keep every trained run folder")
    p.add_argument("--stop-after", type=float, default=None, metavar="MINUTES",
                   help="end this sitting's training after about MINUTES, the run in progress saved at the step "
                        "it reached (not only at its last tenth); the same command goes on from there. The report "
                        "is written as usual, with the runs finished so far")
    p.add_argument("--fresh", action="store_true", help="start a new ledger (the finished runs are forgotten)")
    p.add_argument("--mixed-arithmetic", action="store_true",
                   help="train here even where this CPU's arithmetic (fp32, or bf16 where it is native) differs "
                        "from the ledger's runs'; without it such a sitting is refused before it trains")
    p.add_argument("--only", nargs="*", choices=ARCHS, default=list(ARCHS), help="architectures to measure")
    p.add_argument("--report", default="bsn_arch",
                   help="name of the report (and of its ledger, NAME_ledger.json) in --out; a table of a few "
                        "architectures under a name of its own leaves the whole table as it is")
    p.add_argument("--timing-from", default=None, metavar="REPORT.json",
                   help="take every row's ms and frames/s from an earlier report of this benchmark (e.g. the one "
                        "being refreshed) instead of timing: a report refreshed from its ledger while the machine "
                        "trains; parameters and GMACs are counted again")
    return p


def _ledger(args: argparse.Namespace) -> Ledger | None:
    """The ledger of the runs this table trains (None when it trains none)."""
    if not args.train_steps:
        return None
    clips = sorted(d.name for d in Path(args.data).iterdir() if (d / "meta.json").is_file())
    experiment = {"steps": args.train_steps, "batch_size": 8, "size": list(args.train_size), "clips": clips,
                  "teacher": args.teacher or f"trained first, {args.teacher_steps} steps"}
    try:
        return Ledger(Path(args.out) / f"{args.report}_ledger.json", experiment, fresh=args.fresh)
    except ValueError as e:
        raise RefusedError(str(e)) from None


def _refusals(args: argparse.Namespace, ledger: Ledger | None, timed: dict, timing_from: dict | None) -> None:
    """``RefusedError`` for a sitting that cannot give its rows a time, or would train in other arithmetic than
    the ledger's runs."""
    if timing_from is not None and (untimed := [a for a in table_rows(args.only, ledger) if a not in timed]):
        raise RefusedError(f"--timing-from {args.timing_from} has no timed row for {', '.join(untimed)}: time them "
                           "(without --timing-from) or leave them out of --only")
    missing = [] if ledger is None else runs_left(args, ledger)
    if missing and ledger is not None and not args.mixed_arithmetic:
        why = arithmetic_clash(ledger, precision_name(autocast_dtype(load_config(), torch.device("cpu"))))
        if why:
            raise RefusedError(f"{why} ({', '.join(missing)} left to train)")


def _row(name: str, args: argparse.Namespace, ledger: Ledger | None, runs: dict[str, str], size, timed: dict,
         tmp: Path) -> dict[str, Any]:
    """One architecture's row: counted and timed (or its earlier time), its seeds' IoU from the ledger, its
    own run's IoU."""
    row = measure_arch(name, size, args.repeats, tmp, timed.get(name))
    if ledger is not None:
        keys = sorted((split_key(k), k) for k in ledger.runs)
        recs = {f"seed{seed}": ledger.runs[k] for (arch, seed), k in keys if arch == name}
        row["seeds"] = list(recs)
        row["iou_seeds"] = [r["iou"] for r in recs.values()]
        row["iou"] = fmt(row["iou_seeds"])
        row["last_fifth_gain"] = {sd: r["curve"]["flattened"]["gain"] for sd, r in recs.items()
                                  if r["curve"].get("flattened")}
        gains = row["last_fifth_gain"].values()
        row["flat"] = f"{sum(g < 0.01 for g in gains)} of {len(gains)}"
        row["precision"] = trained_in(recs.values())
    if name in runs:
        row["iou_run"] = held_out_iou(Path(runs[name]), Path(args.data), tmp / f"{name}.json")
    return row


def _markdown(args: argparse.Namespace, rows: list, ledger: Ledger | None, budget: dict | None, diffs: list,
              runs: dict[str, str], size, timing_from: dict | None, names: list[str]) -> list[str]:
    title = "# Architectures (the paper's Table 3)" + (f", {budget['steps']:,} steps" if budget else "")
    lines = [title, "",
             f"Fused D + B at {size[0]}x{size[1]}; frames/s of the fp32 ONNX model in onnxruntime with 2 threads"
             + (f", taken from `{timing_from['report']}` (measured {timing_from['measured_at']} on "
                f"{cpu_named(timing_from['machine'])}), not timed again."
                if timing_from else "."),
             "", "| model | params (M) | GMACs | ms | frames/s | IoU (mean +- std over seeds) | runs flat "
                 "| IoU (own run) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        each = f" ({', '.join(f'{v:.3f}' for v in r['iou_seeds'])})" if len(r.get("iou_seeds", [])) > 1 else ""
        lines.append(f"| {r['model']} | {r['params_m']} | {r['gmacs']} | {r['median_ms']} | {r['fps']} | "
                     f"{r.get('iou', '-')}{each} | {r.get('flat', '-')} | {r.get('iou_run', '-')} |")
    if budget:
        lines += ["", f"IoU: inside V on the held-out clips, every model trained {budget['steps']} steps of batch 8 at "
                      f"{budget['size'][0]}x{budget['size'][1]} with one shared teacher, once per seed, and evaluated "
                      "at that size; runs flat: the last fifth of a run's steps gained under 0.01 validation IoU."]
    if ledger is not None:
        lines.append("")
        for r in rows:
            if r.get("last_fifth_gain"):
                lines.append(f"- `{r['model']}`: last-fifth gain "
                             + ", ".join(f"{sd} {g:+.3f}" for sd, g in r["last_fifth_gain"].items())
                             + "; " + ("precision not recorded" if r["precision"] == [UNRECORDED]
                                       else f"trained in {' and '.join(r['precision'])}"))
        if diffs:
            said = {True: "beyond the seeds' spread", False: "within the seeds' spread",
                    None: "a side has one seed: not told apart yet"}
            lines += ["", "Differences in mean IoU (beyond the spread: larger than the two standard deviations added):",
                      ""]
            lines += [f"- `{d['higher']}` - `{d['lower']}`: {d['difference']:+.3f}, {said[d['beyond_spread']]}"
                      for d in diffs]
        lines += ["", "Runs finished on (the machine of a run's last sitting):", "", *finished_on(ledger, names)]
        figure = f"{args.report}_curves.png"
        if plot_curves(ledger, names, Path(args.out) / figure):
            lines += ["", f"![curves]({figure})"]
    if runs:
        lines += ["", "IoU (own run): " + "; ".join(f"`{k}` {run_budget(Path(v))}" for k, v in runs.items())
                  + "; evaluated at its own training size."]
    return lines


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    if (args.train_steps or args.runs) and not args.data:
        p.error("--train-steps and --runs need --data")
    if args.stop_after is not None and not (args.stop_after > 0 and args.train_steps):
        p.error(f"--stop-after needs --train-steps and a positive number of minutes, got {args.stop_after:g}")
    torch.set_num_threads(2)
    size = (256, 512)
    runs = dict(r.split("=", 1) for r in args.runs)
    timed: dict[str, Any] = {}
    timing_from = None
    if args.timing_from:
        try:
            timed, timing_from = earlier_timing(Path(args.timing_from), size)
        except (OSError, ValueError, KeyError) as e:
            raise RefusedError(f"--timing-from: {e}") from None
    ledger = _ledger(args)
    _refusals(args, ledger, timed, timing_from)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        teacher, stopped = train_seeds(args, ledger, Path(tmp)) if ledger is not None else (None, None)
        names = table_rows(args.only, ledger)
        for name in names:
            rows.append(_row(name, args, ledger, runs, size, timed, Path(tmp)))
            print(rows[-1], flush=True)
    budget = ({"steps": args.train_steps, "batch_size": 8, "size": list(args.train_size),
               "seeds": sorted({split_key(key)[1] for key in ledger.runs}),
               "teacher": str(teacher), "ledger": ledger.path.name} if ledger is not None else None)
    diffs = differences(rows)
    res = {"rows": rows, "size": list(size), "threads": 2, "iou_training": budget, "differences": diffs,
           "iou_run": {k: run_budget(Path(v)) for k, v in runs.items()},
           **({"timing_from": timing_from} if timing_from else {})}
    lines = _markdown(args, rows, ledger, budget, diffs, runs, size, timing_from, names)
    stop = [f"bench_arch: --stop-after {args.stop_after:g} reached with {stopped} unfinished; the same command "
            "goes on from where it stopped"] if stopped is not None else []
    return Report(res, lines, [f"wrote {Path(args.out) / args.report}.json", *stop], name=args.report)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
