"""The training campaign's curves, from a run's history.

    python -m bsn_edge.benchmarks.bench_campaign --run RUN [--name default] [--out benchmarks/results]

Reads ``RUN/history.jsonl`` (``bsn-train`` with ``train.eval_every`` / ``teacher.eval_every``) and
draws the teacher's held-out IoU (road, sidewalk, vehicle, person), B's validation IoU (threshold
swept), D's depth AbsRel and the losses against the samples seen, into ``campaign_NAME.png``, with
a table. It says whether the curve has flattened: the last fifth of the steps recorded gained less
than ``--flat`` IoU (0.01).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: before pyplot is imported
import matplotlib.pyplot as plt

from bsn_edge.train import Run
from bsn_edge.train.run_record import trained_precision

from .runner import RefusedError, Report, run

FLAT_IOU = 0.01


def flattened(records: list[dict[str, Any]], key: str = "val_iou", share: float = 0.2) -> dict[str, Any] | None:
    """Gain of ``key`` over the last ``share`` of the steps recorded: the best value in that stretch
    against the best before it. None with fewer than three records."""
    recs = [r for r in records if key in r]
    if len(recs) < 3:
        return None
    last = recs[-1]["step"]
    cut = last - share * last
    before = [r[key] for r in recs if r["step"] <= cut]
    after = [r[key] for r in recs if r["step"] > cut]
    if not before or not after:
        return None
    gain = max(after) - max(before)
    return {"from_step": int(cut), "to_step": int(last), "gain": gain, "flat": gain < FLAT_IOU}


def run_curve(run: Path, phase: str = "train", key: str = "val_iou") -> dict[str, Any]:
    """A run's validation records of ``phase`` (``train``: B's IoU; ``teacher``: its ``val_miou``),
    whether their last fifth had flattened, the training seconds and the arithmetic it trained in
    (``precision``: every kind its training records name, sorted, step 0 left out as the start's own
    score; ``UNRECORDED`` for records written before the trainer named it)."""
    recs = [r for r in Run(run).history() if r.get("phase") == phase and key in r]
    return {"steps": [r["step"] for r in recs], key: [round(r[key], 4) for r in recs],
            "flattened": flattened(recs, key), "seconds": round(recs[-1]["seconds"]) if recs else None,
            "precision": sorted(trained_precision(recs))}


def plot(teacher: list[dict], student: list[dict], path: Path, title: str) -> None:
    # only the panels with records: a leg that starts from a trained teacher has no teacher curve
    panels = (["teacher"] if teacher else []) + (["validation", "losses"] if student else [])
    n = max(len(panels), 1)
    fig, axes = plt.subplots(1, n, figsize=(5 * n, 4), squeeze=False)
    ax = dict(zip(panels, axes[0], strict=False))
    if teacher:
        x = [r["samples"] for r in teacher]
        for k in ("road", "sidewalk", "vehicle", "person", "miou"):
            ax["teacher"].plot(x, [r[f"val_{k}"] for r in teacher], label=k, lw=2 if k == "miou" else 1)
        ax["teacher"].set_title("teacher: held-out IoU")
        ax["teacher"].set_xlabel("samples")
        ax["teacher"].legend(fontsize=8)
    if student:
        x = [r["samples"] for r in student]
        if any("val_iou" in r for r in student):
            ax["validation"].plot(x, [r.get("val_iou") for r in student], label="B: validation IoU (swept)")
            ax2 = ax["validation"].twinx()
            ax2.plot(x, [r.get("val_abs_rel") for r in student], color="tab:red", label="D: depth AbsRel")
            if any("val_road_abs_rel" in r for r in student):
                ax2.plot(x, [r.get("val_road_abs_rel") for r in student], color="tab:red", ls="--",
                         label="D: road AbsRel 5-40 m")
            ax2.set_ylabel("AbsRel (road dashed)", color="tab:red")
        ax["validation"].set_title("student: validation")
        ax["validation"].set_xlabel("samples")
        ax["validation"].set_ylabel("IoU")
        for k in ("loss", "bce", "kd", "depth"):
            xs = [r["samples"] for r in student if k in r]     # a run started from another: no losses at 0
            ax["losses"].plot(xs, [r[k] for r in student if k in r], label=k)
        ax["losses"].set_yscale("log")
        ax["losses"].set_title("student: training losses\n(mean since the last record)")
        ax["losses"].set_xlabel("samples")
        ax["losses"].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="a bsn-train run folder with history.jsonl")
    p.add_argument("--name", default="default", help="the campaign's name: the report is campaign_NAME in --out")
    p.add_argument("--out", default="benchmarks/results")
    return p


def _teacher_lines(teacher: list[dict[str, Any]], t_flat: dict[str, Any] | None) -> list[str]:
    lines = ["| teacher step | samples | road | sidewalk | vehicle | person | mIoU |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['step']} | {r['samples']} | {r['val_road']:.3f} | {r['val_sidewalk']:.3f} | "
              f"{r['val_vehicle']:.3f} | {r['val_person']:.3f} | {r['val_miou']:.3f} |" for r in teacher]
    if t_flat:
        lines.append(f"\nTeacher over its last fifth (steps {t_flat['from_step']}-{t_flat['to_step']}): mIoU "
                     f"{t_flat['gain']:+.3f}: {'flat' if t_flat['flat'] else 'still rising'}.")
    return [*lines, ""]


def _student_lines(student: list[dict[str, Any]], flat: dict[str, Any] | None) -> list[str]:
    road = any("val_road_abs_rel" in r for r in student)
    lines = ["| step | samples | hours | loss | BCE | KD | depth loss | val IoU | threshold | val AbsRel |"
             + (" val road AbsRel 5-40 m |" if road else ""),
             "|---|---|---|---|---|---|---|---|---|---|" + ("---|" if road else "")]
    nan = float("nan")

    def f(r: dict[str, Any], k: str, spec: str) -> str:    # a run's starting point has no losses
        return format(r[k], spec) if k in r else "-"

    lines += [f"| {r['step']} | {r['samples']} | {r['seconds'] / 3600:.2f} | {f(r, 'loss', '.3f')} | "
              f"{f(r, 'bce', '.3f')} | {f(r, 'kd', '.4f')} | {f(r, 'depth', '.3f')} | "
              f"{r.get('val_iou', nan):.3f} | "
              f"{r.get('val_threshold', nan):.2f} | {r.get('val_abs_rel', nan):.3f} |"
              + (f" {r.get('val_road_abs_rel', nan):.3f} |" if road else "")
              for r in student]
    if flat:
        lines.append(f"\nOver the last fifth (steps {flat['from_step']}-{flat['to_step']}) the validation IoU "
                     f"gained {flat['gain']:+.3f}: {'flattened' if flat['flat'] else 'still rising'} "
                     f"(flat: under {FLAT_IOU}).")
    start = next((r for r in student if r["step"] == 0 and "val_iou" in r), None)
    if start is not None and "val_iou" in student[-1]:
        lines.append(f"From where the run began (step 0, the weights it started from) to its last record the "
                     f"validation IoU moved {student[-1]['val_iou'] - start['val_iou']:+.3f}.")
    return lines


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    trained = Run(args.run)
    hist = trained.history()
    if not hist:
        raise RefusedError(f"{trained.path}: no history.jsonl records (train with train.eval_every > 0)")
    cfg = trained.config()
    teacher = [r for r in hist if r.get("phase") == "teacher"]
    student = [r for r in hist if r.get("phase") == "train"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    png = f"campaign_{args.name}.png"
    total = cfg.get("train", {}).get("steps")
    plot(teacher, student, out / png, f"{cfg.get('model', {}).get('name', '?')}: {len(student)} records, "
                                      f"step {student[-1]['step'] if student else 0} of {total}")
    flat = flattened(student)
    t_flat = flattened(teacher, "val_miou")
    hours = (student[-1]["seconds"] if student else 0.0) / 3600
    t_hours = (teacher[-1]["seconds"] if teacher else 0.0) / 3600
    lines = [f"# Training campaign: {args.name}", "",
             f"Run `{trained.path.name}`: `{cfg.get('model', {}).get('name', '?')}`, {total} steps of batch "
             f"{cfg.get('train', {}).get('batch_size')} planned; teacher {len(teacher)} records "
             f"({t_hours:.2f} h), student {len(student)} records ({hours:.2f} h of training so far).", "",
             f"![curves]({png})", ""]
    if teacher:
        lines += _teacher_lines(teacher, t_flat)
    if student:
        lines += _student_lines(student, flat)
    result = {"run": trained.path.name, "config": cfg, "teacher": teacher, "student": student, "flattened": flat,
              "teacher_flattened": t_flat, "figure": png}
    return Report(result, lines, lines, name=f"campaign_{args.name}")


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
