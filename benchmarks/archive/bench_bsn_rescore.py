"""Table 2's kept runs scored again: without a decision threshold, and on more test clips.

    python -m benchmarks.archive.bench_bsn_rescore --family shared-light --out benchmarks/results \
        --work ~/.cache/bsn-edge/accuracy [--more-test-clips 6]

Each source-style run of :mod:`benchmarks.bench_bsn_accuracy` picks its threshold on its own style's
validation clips and is tested at it, on a few test clips per style. Two things can make its number
say little about the model: a threshold that is wrong for the clips tested, and test clips that
happen to be unlike the training ones. Per run and test style, on the table's test clips and on
``--more-test-clips`` more per style (rendered the same way with the next world seeds):

- ``iou``: at the run's own threshold (on the table's clips, the table's number);
- ``best_iou``: the best any threshold of the sweep gives on the clips scored (an upper bound, chosen
  on them);
- ``ap``: the average precision of the probabilities inside V, next to ``ap_by_chance``, the share of
  positives, which a random ranking gets;
- per clip, IoU and AP, with the clip's light and field of view.

Needs the runs' weights (the table keeps them); runs whose folder is gone are listed as such. A score
newer than its run's weights is read back instead of computed again.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.train import Run

from ..bench_bsn_accuracy import (
    BASELINES,
    COLUMNS,
    FAMILIES,
    STYLES,
    finetune_run,
    ledger_path,
    report_name,
    source_run,
    trained_keys,
    write_clips,
)
from ..common import eval_run, write_result
from ..ledger import Ledger, fmt

FIELDS = ("iou", "best_iou", "best_threshold", "ap", "ap_by_chance")


def evaluated(run: Path, data: Path, out: Path, *extra: str) -> dict[str, Any]:
    """The ``bsn-eval`` report of ``run`` on ``data`` at ``out``: read back if it was made through
    ``run`` after its weights, made (:func:`eval_run`) otherwise."""
    rep = json.loads(out.read_text()) if out.is_file() else {}
    if rep.get("run") != str(run) or out.stat().st_mtime <= Run(run).model_path.stat().st_mtime:
        rep = eval_run(run, data, out, *extra)
    return rep


def score(run: Path, data: Path, out: Path, style: str) -> dict[str, Any]:
    """:data:`FIELDS` of ``run`` over the ``style`` clips in ``data``, and IoU and AP per clip."""
    rep = evaluated(run, data, out, "--clips", "all", "--styles", style, "--no-baselines")
    return {**{k: rep["overall"]["BSN"][k] for k in FIELDS},
            "clips": {c: {"iou": m["BSN"]["iou"], "ap": m["BSN"]["ap"]} for c, m in rep["per_clip"].items()}}


def score_baselines(run: Path, data: Path, out: Path, style: str) -> dict[str, float]:
    """IoU of each baseline over the ``style`` clips in ``data``. The baselines need no training, but
    they read a run: Traversable its D's depth, all three its teacher's segmentation."""
    rep = evaluated(run, data, out, "--clips", "all", "--styles", style)
    return {b: rep["overall"][b]["iou"] for b in BASELINES if b in rep["overall"]}


def baselines_on(scores: dict[str, Any], models: list[str], work: Path, name: str, data: Path) -> dict[str, Any]:
    """The baselines on test set ``name`` (``data``), read through one kept run of ``scores``: the first
    model's (BSN's) if one is kept, trained on the first style, lowest seed first. Which run (None
    when none is kept), and per style :func:`score_baselines`."""
    kept = [k for k, r in scores.items() if "missing" not in r]
    key = min(kept, default=None, key=lambda k: (models.index(scores[k]["model"]),
                                                  STYLES.index(scores[k]["source"]), scores[k]["seed"]))
    if key is None:
        return {"run": None}
    rec = scores[key]
    run = source_run(work, rec["seed"], rec["name"], rec["source"])
    return {"run": key, **{tgt: score_baselines(run, data, work / "rescore" / name / f"baselines_on_{tgt}.json", tgt)
                           for tgt in STYLES}}


def add_table_arguments(p: argparse.ArgumentParser) -> None:
    """``--out``, ``--work`` and ``--family``: where a Table 2 is, for the benchmarks that read its runs."""
    p.add_argument("--out", default="benchmarks/results", help="results folder, where the table's ledger is")
    p.add_argument("--work", default="benchmarks/scratch/accuracy", help="the table's work folder (its runs)")
    p.add_argument("--family", choices=FAMILIES, default=FAMILIES[0], help="whose table (default %(default)s)")


def read_table(out: Path, family: str, prog: str) -> Ledger | None:
    """The ledger of ``family``'s table, or None after saying why there is none."""
    try:
        return Ledger.read(ledger_path(out, family))
    except (FileNotFoundError, ValueError) as e:
        print(f"{prog}: {e} (run benchmarks.bench_bsn_accuracy --family {family} first)")
        return None


def clip_order(name: str) -> tuple[str, int]:
    """Sort key of a clip named ``<style>_<n>``: by style, then by number."""
    style, n = name.rsplit("_", 1)
    return style, int(n)


def score_path(work: Path, test_set: str, seed: int, run: Path, style: str) -> Path:
    """Where the score of ``run`` (of ``seed``) on the ``style`` clips of ``test_set`` is kept."""
    return work / "rescore" / test_set / f"seed{seed}_{run.name}_on_{style}.json"


def score_runs(ledger: Ledger, work: Path, test_sets: dict[str, Path]) -> dict[str, Any]:
    """Per trained key of the ledger: its model, source style, seed, threshold and, per test set and
    style, :func:`score`; ``missing`` instead of scores when the run's weights are gone."""
    out: dict[str, Any] = {}
    for key, label, src, seed in trained_keys(ledger):
        name = ledger.experiment["models"][label]
        run = source_run(work, seed, name, src)
        rec: dict[str, Any] = {"model": label, "name": name, "source": src, "seed": seed}
        if not Run(run).model_path.is_file():
            out[key] = {**rec, "missing": str(run)}
            continue
        rec["threshold"] = Run(run).card().threshold
        for name, data in test_sets.items():
            rec[name] = {tgt: score(run, data, score_path(work, name, seed, run, tgt), tgt) for tgt in STYLES}
        rec["finetuned"] = {}
        for tgt in STYLES:
            ft = finetune_run(run, tgt)
            if tgt != src and Run(ft).model_path.is_file():
                rec["finetuned"][tgt] = {name: score(ft, data, score_path(work, name, seed, ft, tgt), tgt)
                                         for name, data in test_sets.items()}
        out[key] = rec
    return out


def describe_clips(folders: list[Path]) -> dict[str, str]:
    """Light and horizontal field of view of each synthetic clip, by clip name."""
    out = {}
    for root in folders:
        for seq in sorted(p for p in root.iterdir() if p.is_dir()):
            path = SequenceFolder(seq).synth_config_path
            if path.is_file():
                c = json.loads(path.read_text())
                out[seq.name] = f"{c['light']}, {c['rig']['hfov_deg']:.0f} deg"
    return out


def arms_by_clip(scores: dict[str, dict[str, Any]], heads: dict[str, str], described: dict[str, str]) -> list[str]:
    """A markdown table of arms side by side, a row per clip (``IoU / AP``), then each test set's
    pooled scores; ``scores[arm][test set]`` as :func:`score` gives them, ``heads`` the arms' column
    titles in order (the pooled lines name each arm by its title up to `` (``)."""
    arms = list(heads)
    lines = ["| clip | light, field of view | " + " | ".join(heads.values()) + " |", "|---" * (2 + len(arms)) + "|"]
    per_clip: dict[str, dict[str, dict[str, float]]] = {}
    for arm in arms:
        for part in scores[arm].values():
            for clip, m in part["clips"].items():
                per_clip.setdefault(clip, {})[arm] = m
    for clip in sorted(per_clip, key=clip_order):
        cells = [f"{per_clip[clip][a]['iou']:.3f} / {per_clip[clip][a]['ap']:.3f}" if a in per_clip[clip] else "-"
                 for a in arms]
        lines.append(f"| {clip} | {described.get(clip, '-')} | " + " | ".join(cells) + " |")
    lines += ["", "Over all the clips (pooled per test set, IoU / AP):", ""]
    for n in scores[arms[0]]:
        lines.append(f"- `{n}`: " + "; ".join(
            f"{heads[a].split(' (')[0]} {scores[a][n]['iou']:.3f} / {scores[a][n]['ap']:.3f}" for a in arms))
    return lines


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def markdown(family: str, models: list[str], scores: dict[str, Any], sets: dict[str, int],
             clips: dict[str, str], baselines: dict[str, Any]) -> str:
    names = list(sets)
    lines = [f"# Table 2 ({family}) scored again: without a threshold, and on more test clips", "",
             "Every kept source-style run of the table on each style's test clips: IoU at the threshold its "
             "own style's validation chose, the best IoU any threshold gives on the clips scored (an upper "
             "bound: chosen on them) and the average precision inside V (AP by chance: the share of "
             "positives). Test sets: " + "; ".join(f"`{n}`, {k} clips per style" for n, k in sets.items()) + ".",
             "", "| run | threshold | test | " + " | ".join(f"{n}: IoU / best / AP (chance)" for n in names) + " |",
             "|---" * (3 + len(names)) + "|"]
    groups: dict[tuple[str, str, str, str], list[dict[str, Any]]] = {}
    per_clip: dict[tuple[str, str], list[float]] = {}
    for key, rec in scores.items():
        if "missing" in rec:
            lines.append(f"| {key} | - | - | " + " | ".join("weights gone" for _ in names) + " |")
            continue
        for tgt in STYLES:
            cells = []
            for n in names:
                m = rec[n][tgt]
                groups.setdefault((rec["model"], rec["source"], tgt, n), []).append(m)
                cells.append(f"{m['iou']:.3f} / {m['best_iou']:.3f} / {_f(m['ap'])} ({_f(m['ap_by_chance'])})")
                for clip, c in m["clips"].items():
                    per_clip.setdefault((clip, rec["source"]), []).append(c["iou"])
            lines.append(f"| {key} | {rec['threshold']:.2f} | {tgt} | " + " | ".join(cells) + " |")
    lines += ["", "Per model, source and test style, over the seeds kept (mean +- std):", "",
              "| model | source -> test | test set | IoU | best IoU | AP |", "|---" * 6 + "|"]
    for (label, src, tgt, n), ms in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2],
                                                                          names.index(kv[0][3]))):
        lines.append(f"| {label} | {src} -> {tgt} | {n} | {fmt(m['iou'] for m in ms)} | "
                     f"{fmt(m['best_iou'] for m in ms)} | {fmt(m['ap'] for m in ms if m['ap'] is not None)} |")
    fresh = names[-1]
    lines += ["", f"The table's layout on the `{fresh}` clips: IoU at each run's own threshold, mean +- std over "
              "the kept runs (a fine-tuned cell only where the fine-tuned run's weights were kept):", "",
              "| model | " + " | ".join(f"{s} -> {t}{', fine-tuned' if ft else ''}" for s, t, ft in COLUMNS) + " |",
              "|---" * (len(COLUMNS) + 1) + "|"]
    for label in models:
        vals = []
        for src, tgt, ft in COLUMNS:
            runs = [r for r in scores.values() if r["model"] == label and r["source"] == src and "missing" not in r]
            parts = [r["finetuned"].get(tgt, {}).get(fresh) if ft else r[fresh][tgt] for r in runs]
            vals.append(fmt(p["iou"] for p in parts if p))
        lines.append(f"| {label} | " + " | ".join(vals) + " |")
    if baselines.get("run"):
        for b in BASELINES:
            if all(b in baselines[t] for _, t, _ in COLUMNS):
                lines.append(f"| {b} | " + " | ".join(f"{baselines[t][b]:.3f}" for _, t, _ in COLUMNS) + " |")
        lines += ["", f"Baselines (no training): Traversable reads the depth of `{baselines['run']}`'s D, all three "
                  "the shared teacher's segmentation."]
    lines += ["", "Per test clip, IoU at each run's own threshold, mean +- std over the kept runs trained on "
              "each style:", "", "| clip | light, field of view | " + " | ".join(f"{s}-trained" for s in STYLES)
              + " |", "|---" * (2 + len(STYLES)) + "|"]
    for clip in sorted({c for c, _ in per_clip}, key=clip_order):
        lines.append(f"| {clip} | {clips.get(clip, '-')} | "
                     + " | ".join(fmt(per_clip.get((clip, s), [])) for s in STYLES) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_table_arguments(p)
    p.add_argument("--more-test-clips", type=int, default=6,
                   help="more test clips per style beyond the table's (default %(default)s; 0: the table's only)")
    args = p.parse_args(argv)
    if args.more_test_clips < 0:
        p.error("--more-test-clips must be 0 or more")
    out, work = Path(args.out), Path(args.work)
    ledger = read_table(out, args.family, "bench_bsn_rescore")
    if ledger is None:
        return 2
    ex = ledger.experiment
    first = ex["train_clips_per_style"] + ex["test_clips_per_style"]
    test_sets = {"table": work / "test"}
    sets = {"table": ex["test_clips_per_style"]}
    if args.more_test_clips:
        test_sets["more"] = write_clips(work / "test_more", range(first, first + args.more_test_clips),
                                        ex["frames_per_clip"], tuple(ex["size"]))
        sets["more"] = args.more_test_clips
    scores = score_runs(ledger, work, test_sets)
    fresh = list(test_sets)[-1]
    baselines = baselines_on(scores, list(ex["models"]), work, fresh, test_sets[fresh])
    name = f"{report_name(args.family)}_rescore"
    path = write_result(out, name, {"family": args.family, "ledger": ledger.path.name, "test_sets": sets,
                                    "runs": scores, "baselines": {fresh: baselines}},
                        markdown(args.family, list(ex["models"]), scores, sets,
                                 describe_clips(list(test_sets.values())), baselines))
    print((out / f"{name}.md").read_text())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
