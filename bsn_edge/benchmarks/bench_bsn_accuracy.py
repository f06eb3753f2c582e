"""The paper's Table 2 on held-out synthetic clips, with seeds: BSN, BSN-D, BSN-KD and the three
baselines, trained on one style, tested on both, with and without fine-tuning on 20 % of the target
style; every trained cell as mean +- std over ``--seeds``.

    python -m bsn_edge.benchmarks.bench_bsn_accuracy --out benchmarks/results [--seeds 0 1 2] [--steps 3000] \
        [--family small-light|shared-light]

BSN is the ``--family`` architecture, BSN-D and BSN-KD its ``-d`` and ``-kd`` registry entries.

At the research scale (``--size``, 128x256 by default: a quarter of the runtime's pixels per step).
One segmentation teacher is trained on the training clips of both styles (the role an off-the-shelf
segmenter plays in the paper) and shared by every run and by the baselines. Fine-tuning starts from
the source-style run and trains on 20 % of the target style's training clips. Every run records its
validation IoU every tenth of its steps, so the table says whether each row had flattened (the last
fifth of its steps gained under 0.01) and draws the curves.

A whole table is many CPU-hours: each finished run is written to the family's ledger
(``bsn_accuracy_ledger.json``, ``bsn_accuracy_shared-light_ledger.json``) in ``--out`` at once
(:mod:`bsn_edge.benchmarks.ledger`), so the command can be stopped and run again, on any machine, and
trains only what is missing (a run stopped part-way goes on from its last tenth); seeds are the
outer loop, so a partial table holds whole seeds. The report is written from the ledger after every
run.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path
from typing import Any

from bsn_edge.cli import label as label_cli
from bsn_edge.cli.common import parse_size
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.train import Run

from .bench_campaign import run_curve
from .common import eval_run, records, train_run, write_result
from .ledger import Ledger, exceeds_spread, fmt, mean_std

FAMILIES = ("small-light", "shared-light")   # an architecture with its -d and -kd ablations in the registry


def family_models(family: str) -> dict[str, str]:
    """BSN and its ablations, BSN-D and BSN-KD, as registry names of ``family``."""
    return {"BSN": family, "BSN-D": f"{family}-d", "BSN-KD": f"{family}-kd"}


def report_name(family: str) -> str:
    """The report of a family's table (``bsn_accuracy`` for the first, the others by name); its ledger
    is ``<report>_ledger.json``."""
    return "bsn_accuracy" if family == FAMILIES[0] else f"bsn_accuracy_{family}"
STYLES = ("town", "suburb")
BASELINES = ("Traversable", "Detection-2D", "Detection-3D")
METRICS = ("iou", "recall", "precision")
FINETUNE_LR = 1e-4  # a tenth of training's: at 1e-3, 20 % of the target style erases what was learnt
CURVE_RECORDS = 10  # validation records per run


def ledger_path(out: Path, family: str) -> Path:
    """The ledger of ``family``'s table in the results folder ``out``."""
    return out / f"{report_name(family)}_ledger.json"


def run_key(label: str, src: str, seed: int) -> str:
    """A trained run's key in the ledger: ``BSN/town/seed0``."""
    return f"{label}/{src}/seed{seed}"


def trained_keys(ledger: Ledger) -> list[tuple[str, str, str, int]]:
    """Every trained run in ``ledger`` as (key, model label, source style, seed), in key order."""
    out = []
    for key in sorted(ledger.runs):
        parts = key.split("/")
        if len(parts) == 3 and parts[2].startswith("seed"):
            out.append((key, parts[0], parts[1], int(parts[2][4:])))
    return out


def source_run(work: Path, seed: int, name: str, src: str) -> Path:
    """The folder of the run of registry model ``name`` trained on style ``src`` with ``seed``."""
    return work / "runs" / f"seed{seed}" / f"{name}_{src}"


def finetune_run(source: Path, tgt: str) -> Path:
    """The folder of ``source`` fine-tuned on style ``tgt``."""
    return source.with_name(f"{source.name}_ft_{tgt}")


def write_clips(root: Path, numbers: range, frames: int, size: tuple[int, int]) -> Path:
    """Render clips ``<style>_<n>`` of both styles (world seed ``1000 + n``) into ``root`` and label
    them; finished clips and labels are skipped."""
    for style in STYLES:
        for i in numbers:
            seq = root / f"{style}_{i}"
            if not (seq / "meta.json").exists():
                write_clip(SynthConfig(frames=frames, style=style, seed=1000 + i, height=size[0], width=size[1]),
                           seq, video=False)
    label_cli.main([*map(str, sorted(root.iterdir())), "--jobs", "2"])
    return root


def make_data(work: Path, train_clips: int, test_clips: int, frames: int, size: tuple[int, int]
              ) -> tuple[Path, Path]:
    """The table's training and test clips (rendered and labelled once)."""
    return (write_clips(work / "train", range(train_clips), frames, size),
            write_clips(work / "test", range(train_clips, train_clips + test_clips), frames, size))


def _metrics(report: dict[str, Any], name: str) -> dict[str, float]:
    m = report["overall"][name]
    return {k: round(m[k], 4) for k in METRICS}


def experiment(args: argparse.Namespace) -> dict[str, Any]:
    """What a ledger's runs share; a ledger of another experiment is not mixed into."""
    return {"steps": args.steps, "finetune_steps": args.finetune_steps, "finetune_lr": FINETUNE_LR,
            "teacher_steps": args.teacher_steps, "batch_size": 8, "size": list(args.size),
            "train_clips_per_style": args.train_clips, "test_clips_per_style": args.test_clips,
            "frames_per_clip": args.frames, "models": family_models(args.family)}


def shared_settings(ex: dict[str, Any]) -> list[str]:
    """``bsn-train`` settings every run of experiment ``ex`` shares (the teacher's run included)."""
    h, w = ex["size"]
    return [f"data.size=[{h}, {w}]", "data.val_fraction=0.25", f"train.batch_size={ex['batch_size']}",
            "train.eval_frames=128"]


def teacher_settings(work: Path) -> list[str]:
    """``bsn-train`` settings that make a run distil from the table's shared teacher."""
    return [f"teacher.checkpoint=\"{teacher_run(work) / 'teacher'}\""]


def source_settings(ex: dict[str, Any], work: Path, name: str, src: str, seed: int) -> list[str]:
    """``bsn-train`` settings of the table's run of registry model ``name`` trained on style ``src``
    with ``seed`` (its data is the table's training clips)."""
    return [*shared_settings(ex), *teacher_settings(work), f'model.name="{name}"', f"train.steps={ex['steps']}",
            *records(ex["steps"], CURVE_RECORDS), f"train.seed={seed}", f'data.train_styles=["{src}"]']


def teacher_run(work: Path) -> Path:
    """The folder of the table's shared teacher in ``work``."""
    return work / "runs" / "teacher"


def prepare(work: Path, ex: dict[str, Any]) -> tuple[Path, Path, dict[str, Any] | None]:
    """The clips and the shared teacher of experiment ``ex`` in ``work``, each made where missing:
    (training clips, test clips, the teacher's validation curve if it was trained by this call,
    None if it was there already)."""
    train, test = make_data(work, ex["train_clips_per_style"], ex["test_clips_per_style"], ex["frames_per_clip"],
                            tuple(ex["size"]))
    teacher = teacher_run(work)
    trained_here = not Run(teacher).checkpoint_path.is_file()
    train_run(train, teacher, [*shared_settings(ex), 'model.name="small-light"', f"teacher.steps={ex['teacher_steps']}",
                               f"teacher.eval_every={max(1, ex['teacher_steps'] // CURVE_RECORDS)}",
                               "train.steps=1", "train.checkpoint_every=1"])
    return train, test, (run_curve(teacher, "teacher", "val_miou") if trained_here else None)


def run_table(work: Path, ledger: Ledger, seeds: list[int], keep_runs: bool, on_record=None) -> None:
    """Train and evaluate every (seed, model, source style) missing from ``ledger``."""
    ex = ledger.experiment
    train, test, trained = prepare(work, ex)
    ft_steps = ex["finetune_steps"]
    common = shared_settings(ex)
    if "teacher" not in ledger:
        ledger.put("teacher", {**(trained or run_curve(teacher_run(work), "teacher", "val_miou")), "retrained": []})
    elif trained is not None:
        # the work folder was lost (another machine): the same recipe trained again, the runs after
        # this point distil from it; the ledger says so
        rec = ledger.runs["teacher"]
        ledger.put("teacher", {**rec, "retrained": [*rec.get("retrained", []), trained["val_miou"][-1:]]})
    tsets = teacher_settings(work)
    for seed in seeds:
        for label, name in ledger.experiment["models"].items():
            for src in STYLES:
                key = run_key(label, src, seed)
                if key in ledger:
                    continue
                t0 = time.perf_counter()
                base = source_run(work, seed, name, src)
                train_run(train, base, source_settings(ex, work, name, src, seed))
                record: dict[str, Any] = {"curve": run_curve(base), "test": {}, "finetuned": {}}
                for tgt in STYLES:
                    with_baselines = f"baselines/{tgt}" not in ledger
                    extra = ("--clips", "all", "--styles", tgt, *(() if with_baselines else ("--no-baselines",)))
                    rep = eval_run(base, test, work / "eval" / f"seed{seed}_{base.name}_on_{tgt}.json", *extra)
                    record["test"][tgt] = _metrics(rep, "BSN")
                    if with_baselines:
                        ledger.put(f"baselines/{tgt}", {b: _metrics(rep, b) for b in BASELINES if b in rep["overall"]})
                    if tgt == src:
                        continue
                    ft = finetune_run(base, tgt)
                    train_run(train, ft, [*common, *tsets, f'model.name="{name}"', f"train.steps={ft_steps}",
                                          *records(ft_steps, CURVE_RECORDS), f"train.seed={seed}",
                                          f'data.train_styles=["{tgt}"]', "data.fraction=0.2",
                                          f'train.init="{base}"', f"train.lr={FINETUNE_LR}"])
                    rep = eval_run(ft, test, work / "eval" / f"seed{seed}_{ft.name}_on_{tgt}.json",
                                   "--clips", "all", "--styles", tgt, "--no-baselines")
                    record["finetuned"][tgt] = {**_metrics(rep, "BSN"), "curve": run_curve(ft)}
                    if not keep_runs:
                        keep_weights_only(ft)
                record["seconds"] = round(time.perf_counter() - t0)
                record["teacher"] = len(ledger.runs["teacher"]["retrained"])   # 0: the first teacher
                ledger.put(key, record)
                if not keep_runs:
                    keep_weights_only(base)
                if on_record:
                    on_record()


def keep_weights_only(run: Path) -> None:
    """Drop what only resuming needs (the optimizer's state, about 3x the weights) and keep the
    finished run's weights, card and history, so the ledger's runs can be tested again (a revised
    test set, another fine-tuning protocol) without training them again."""
    Run(run).state_path.unlink(missing_ok=True)


# the source style first, then the other without and with fine-tuning
COLUMNS = [(src, tgt, ft) for src in STYLES for tgt in sorted(STYLES, key=lambda t: t != src)
           for ft in ((False,) if src == tgt else (False, True))]


def cells(ledger: Ledger, label: str, src: str, tgt: str, finetuned: bool, metric: str = "iou") -> list[float]:
    """``metric`` of every seed of ``label`` trained on ``src`` and tested on ``tgt``."""
    out = []
    for key, lab, s, _ in trained_keys(ledger):
        if (lab, s) == (label, src):
            rec = ledger.runs[key]
            part = rec["finetuned"].get(tgt) if finetuned else rec["test"].get(tgt)
            if part:
                out.append(part[metric])
    return out


def table(ledger: Ledger) -> dict[str, Any]:
    """Per model and column: the seeds' IoUs, mean and std; the ablations' differences to BSN."""
    rows = {}
    for label in ledger.experiment["models"]:
        rows[label] = {f"{src}->{tgt}{' ft' if ft else ''}": cells(ledger, label, src, tgt, ft)
                       for src, tgt, ft in COLUMNS}
    for b in BASELINES:
        rows[b] = {f"{src}->{tgt}{' ft' if ft else ''}": ([ledger.runs[f"baselines/{tgt}"][b]["iou"]]
                                                           if f"baselines/{tgt}" in ledger
                                                           and b in ledger.runs[f"baselines/{tgt}"] else [])
                   for src, tgt, ft in COLUMNS}
    beyond: dict[str, Any] = {}
    for abl in ("BSN-D", "BSN-KD"):
        beyond[abl] = {}
        for col, vals in rows["BSN"].items():
            other = rows[abl][col]
            if vals and other:
                diff = mean_std(vals)[0] - mean_std(other)[0]
                beyond[abl][col] = {"bsn_minus": round(diff, 4), "beyond_spread": exceeds_spread(vals, other)}
    return {"rows": rows, "ablations": beyond}


def plot_curves(ledger: Ledger, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = ledger.experiment["models"]
    fig, axes = plt.subplots(1, len(models) + 1, figsize=(5 * (len(models) + 1), 3.6), sharey=False)
    t = ledger.get("teacher")
    if t:
        axes[0].plot(t["steps"], t["val_miou"], color="k")
        axes[0].set_title("teacher: validation mIoU")
        axes[0].set_xlabel("step")
    for ax, label in zip(axes[1:], models, strict=True):
        for key, lab, src, seed in trained_keys(ledger):
            if lab == label:
                c = ledger.runs[key]["curve"]
                ax.plot(c["steps"], c["val_iou"], color="tab:blue" if src == "town" else "tab:orange",
                        alpha=0.8, label=f"{src} seed{seed}")
        ax.set_title(f"{label}: validation IoU (own style)")
        ax.set_xlabel("step")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "not run yet", ha="center", va="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def markdown(ledger: Ledger, tab: dict[str, Any], figure: str) -> str:
    ex = ledger.experiment
    seeds = sorted({f"seed{seed}" for *_, seed in trained_keys(ledger)})
    head = " | ".join(f"{s} -> {t}{', fine-tuned' if ft else ''}" for s, t, ft in COLUMNS)
    lines = ["# BlindSpotNet accuracy (the paper's Table 2, synthetic world), with seeds", "",
             f"Held-out test clips ({ex['test_clips_per_style']} per style), IoU inside V, mean +- std over the "
             f"seeds run so far ({', '.join(seeds) or 'none'}). Each run: {ex['steps']} steps of batch "
             f"{ex['batch_size']} at {ex['size'][0]}x{ex['size'][1]}; fine-tuning: {ex['finetune_steps']} more steps "
             f"at lr {ex['finetune_lr']:g} on 20 % of the target style's training clips; one teacher of "
             f"{ex['teacher_steps']} steps shared by all. Baselines need no training (one value).", "",
             f"| model | {head} |", "|---" * (len(COLUMNS) + 1) + "|"]
    for label, row in tab["rows"].items():
        vals = [fmt(v) if label in ex["models"] else (f"{v[0]:.3f}" if v else "-") for v in row.values()]
        lines.append(f"| {label} | " + " | ".join(vals) + " |")
    lines += ["", "BSN against its ablations, per column: mean difference (BSN minus ablation), and whether it "
                  "exceeds the seeds' spread (larger than the two standard deviations added):", ""]
    for abl, cols in tab["ablations"].items():
        parts = [f"{col} {v['bsn_minus']:+.3f}{' *' if v['beyond_spread'] else ''}" for col, v in cols.items()]
        lines.append(f"- BSN - {abl}: " + ("; ".join(parts) if parts else "not run yet"))
    lines += ["", "(`*`: beyond the spread.)", "", "Curves (validation IoU every tenth of a run's steps; "
              "flat: the last fifth gained under 0.01):", ""]
    for label in ex["models"]:
        gains = [ledger.runs[k]["curve"]["flattened"]["gain"] for k, lab, *_ in trained_keys(ledger)
                 if lab == label and ledger.runs[k]["curve"].get("flattened")]
        if gains:
            flat = sum(g < 0.01 for g in gains)
            lines.append(f"- {label}: {flat} of {len(gains)} runs flat; last-fifth gain {fmt(gains)}")
    t = ledger.get("teacher")
    if t and t.get("flattened"):
        lines.append(f"- teacher: validation mIoU {t['val_miou'][-1]:.3f}, last-fifth gain "
                     f"{t['flattened']['gain']:+.3f}")
        for i, again in enumerate(t.get("retrained", []), start=1):
            keys = [k for k, *_ in trained_keys(ledger) if ledger.runs[k].get("teacher") == i]
            lines.append(f"- the teacher trained again by the same recipe (its work folder was lost), validation "
                         f"mIoU {again[-1]:.3f}; the runs after it distil from it: {', '.join(keys) or 'none yet'}")
    lines += ["", f"![curves]({figure})"]
    return "\n".join(lines)


def write_report(ledger: Ledger, out: Path) -> Path:
    name = report_name(ledger.experiment["models"]["BSN"])
    figure = f"{name}_curves.png"
    out.mkdir(parents=True, exist_ok=True)
    plot_curves(ledger, out / figure)
    tab = table(ledger)
    return write_result(out, name, {"experiment": ledger.experiment, **tab, "figure": figure,
                                              "ledger": ledger.path.name}, markdown(ledger, tab, figure))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results", help="results folder (the ledger is kept here too)")
    p.add_argument("--work", default="benchmarks/scratch/accuracy", help="clips and runs are kept here")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="training seeds (default 0 1 2)")
    p.add_argument("--size", type=parse_size, default=(128, 256), metavar="HxW",
                   help="clip and training size (default 128x256)")
    p.add_argument("--steps", type=int, default=3000, help="steps of batch 8 per run (default 3000)")
    p.add_argument("--finetune-steps", type=int, default=600)
    p.add_argument("--teacher-steps", type=int, default=3000)
    p.add_argument("--train-clips", type=int, default=8, help="training clips per style")
    p.add_argument("--test-clips", type=int, default=2, help="test clips per style")
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--family", choices=FAMILIES, default=FAMILIES[0],
                   help="the architecture of BSN (its -d and -kd registry entries are the ablations); each "
                        "family has its own ledger and report (default %(default)s)")
    p.add_argument("--keep-runs", action="store_true",
                   help="keep every run folder whole, with its training state (about 210 MB each); by default "
                        "only each run's weights, card and history are kept (about 46 MB each for shared-light)")
    p.add_argument("--report-only", action="store_true", help="write the report from the ledger, train nothing")
    p.add_argument("--fresh", action="store_true", help="delete the work folder and start a new ledger")
    args = p.parse_args(argv)
    for name in ("steps", "finetune_steps", "teacher_steps", "train_clips", "test_clips", "frames"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1")
    work, out = Path(args.work), Path(args.out)
    if args.fresh:
        shutil.rmtree(work, ignore_errors=True)
    try:
        ledger = Ledger(ledger_path(out, args.family), experiment(args), fresh=args.fresh)
    except ValueError as e:
        print(f"bench_bsn_accuracy: {e}")
        return 2
    if not args.report_only:
        run_table(work, ledger, args.seeds, args.keep_runs, on_record=lambda: write_report(ledger, out))
    path = write_report(ledger, out)
    print((out / f"{report_name(args.family)}.md").read_text())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
