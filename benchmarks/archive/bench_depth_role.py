"""Where does depth reach B? A controlled check of why BSN-D is not below BSN in Table 2.

    python -m benchmarks.archive.bench_depth_role --family shared-light --out benchmarks/results \
        --work ~/.cache/bsn-edge/accuracy [--seeds 1 2] [--style town]

In the paper D and B are two networks, and BSN-D's B has no depth at all. In a shared-encoder
family B and D read one encoder, which D's depth loss trains as much as B's loss does: BSN-D's B
still learns on features shaped by depth. Three questions, on the kept runs of the table's seeds:

- Does BSN's B use the depth it is given? BSN scored as trained, and again with its depth input
  flattened at test time (each frame's depth feature replaced by its mean over the frame: the
  frame's overall scale kept, where things are lost). A B that reads depth loses accuracy.
- Does BSN-D's B draw on depth through the shared encoder? BSN-D trained again with the same
  recipe and seed but without the depth loss (``train.depth_weight=0``), so nothing in the network
  learns depth. If its B falls below BSN-D's, depth reaches B through the encoder.
- Would better depth help? BSN given the ground-truth depth instead of D's at test time, and BSN
  trained and scored with it throughout (the family's ``-oracle`` model, same recipe and seed).
  If the oracle stands clearly above BSN, D's depth is what holds B back; if not, B makes little
  of depth at this budget, however good.

All are scored on the style's test clips of the table and of the rescore (``bench_bsn_rescore``
renders those), at each run's own threshold and by average precision.

The table's kept runs live in ``--work``, which does not travel with the results. With ``--retrain``
a seed whose kept BSN or BSN-D run is gone has it trained again by the table's recipe and seed (the
table's clips and teacher made again first where they are gone too); the report compares each source
run's IoU on the table's test clips with the table's record, so it says whether the arms stand on the
table's own runs. Seeds already in the report and not asked for again keep their recorded scores.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from bsn_edge.models import MODELS
from bsn_edge.train import Run

from ..archive.bench_bsn_rescore import (
    add_table_arguments,
    arms_by_clip,
    describe_clips,
    read_table,
    score,
    score_path,
)
from ..bench_bsn_accuracy import (
    STYLES,
    prepare,
    report_name,
    run_key,
    source_run,
    source_settings,
    teacher_run,
)
from ..bench_campaign import run_curve
from ..common import train_run, write_result
from ..ledger import Ledger, fmt

ARMS = {
    "BSN": "BSN as trained",
    "BSN flat depth": "BSN, its depth input flattened at test time",
    "BSN-D": "BSN-D as trained",
    "BSN-D no depth loss": "BSN-D trained without the depth loss",
    "BSN true depth": "BSN, given the ground-truth depth instead of D's at test time",
    "BSN oracle": "BSN trained and scored with the ground-truth depth as B's input",
}

SOURCE = {True: "the table's own run", False: "trained again by the table's recipe", None: "not in the table"}


@contextmanager
def flattened_depth_input() -> Iterator[None]:
    """While open, B sees each frame's depth feature as its mean over the frame (both model layouts
    take it from ``bsn_edge.models.bsn.depth_feature``)."""
    import bsn_edge.models.bsn as bsn

    real = bsn.depth_feature

    def flat(depth):
        f = real(depth)
        return f.mean(dim=(2, 3), keepdim=True).expand_as(f)

    bsn.depth_feature = flat
    try:
        yield
    finally:
        bsn.depth_feature = real


@contextmanager
def true_depth_input() -> Iterator[None]:
    """While open, every model a run loads gives B the ground-truth depth instead of D's (the
    evaluator passes it to an ``oracle_depth`` model); the weights are the run's own."""
    real = Run._build

    def as_oracle(self, card, state):
        model = real(self, card, state)
        model.oracle_depth = model.use_depth
        return model

    Run._build = as_oracle
    try:
        yield
    finally:
        Run._build = real


def markdown(result: dict[str, Any], described: dict[str, str]) -> str:
    arms, seeds = list(ARMS), result["seeds"]
    lines = [f"# Where does depth reach B? ({result['family']}, trained on {result['style']}, "
             f"seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))})", "",
             "Scored on the style's test clips at each model's own threshold: IoU / average precision.", ""]
    lines += [f"- **{a}**: {ARMS[a]}" for a in arms]
    if len(seeds) > 1:
        lines += ["", "Pooled over each test set's clips, mean +- std over the seeds (IoU; AP):", "",
                  "| arm | " + " | ".join(f"`{n}` IoU | `{n}` AP" for n in result["tests"]) + " |",
                  "|---" * (1 + 2 * len(result["tests"])) + "|"]
        for a in arms:
            cells = [fmt(result["scores"][str(sd)][a][n][k] for sd in seeds)
                     for n in result["tests"] for k in ("iou", "ap")]
            lines.append(f"| {a} | " + " | ".join(cells) + " |")
    for sd in seeds:
        lines += ["", f"## Seed {sd}", ""]
        runs = result.get("source_runs", {}).get(str(sd))
        if runs:
            lines += ["Source runs, IoU on the table's test clips as scored here and as the table recorded it: "
                      + "; ".join(f"{label} {r['here']} / {r['table']} ({SOURCE[r['same_run']]})"
                                  for label, r in runs.items()) + "."]
        teacher = result.get("teacher", {}).get(str(sd))
        if teacher and None not in teacher.values():
            lines.append(f"The teacher they distil from: validation mIoU {teacher['here']:.3f} (the table's first "
                         f"teacher: {teacher['table']:.3f}).")
        lines.append("")
        lines += arms_by_clip(result["scores"][str(sd)], {a: a for a in arms}, described)
        lines += [""] + [f"Validation IoU of {a} over its training: {', '.join(f'{v:.3f}' for v in curve)}."
                         for a, curve in result["val_iou"][str(sd)].items() if curve]
    return "\n".join(lines).rstrip() + "\n"


def seed_arms(ex: dict[str, Any], work: Path, seed: int, style: str, tests: dict[str, Path], oracle_name: str
              ) -> tuple[dict[str, Any], dict[str, list[float]]]:
    """Every arm's scores of one seed (training the two runs of its own first, or going on with
    them; ``oracle_name`` is the registry's oracle of the family) and the validation curves of those two."""
    runs = {label: source_run(work, seed, ex["models"][label], style) for label in ("BSN", "BSN-D")}
    no_depth = work / "depth_role" / f"seed{seed}_{ex['models']['BSN-D']}_{style}_no_depth_loss"
    train_run(work / "train", no_depth,
              [*source_settings(ex, work, ex["models"]["BSN-D"], style, seed), "train.depth_weight=0"])
    oracle = work / "depth_role" / f"seed{seed}_{oracle_name}_{style}"
    train_run(work / "train", oracle, source_settings(ex, work, oracle_name, style, seed))
    scores_dir = work / "depth_role" / "scores"
    scores: dict[str, Any] = {
        label: {n: score(run, d, score_path(work, n, seed, run, style), style)
                for n, d in tests.items()} for label, run in runs.items()}
    with flattened_depth_input():
        scores["BSN flat depth"] = {n: score(runs["BSN"], d, scores_dir / f"seed{seed}_flat_{n}.json", style)
                                    for n, d in tests.items()}
    with true_depth_input():
        scores["BSN true depth"] = {n: score(runs["BSN"], d, scores_dir / f"seed{seed}_true_depth_{n}.json", style)
                                    for n, d in tests.items()}
    curves = {}
    for label, run in {"BSN-D no depth loss": no_depth, "BSN oracle": oracle}.items():
        scores[label] = {n: score(run, d, scores_dir / f"{run.name}_{n}.json", style) for n, d in tests.items()}
        curves[label] = run_curve(run)["val_iou"]
    return {a: scores[a] for a in ARMS}, curves


def source_check(ledger: Ledger, scores: dict[str, Any], seed: int, style: str) -> dict[str, Any]:
    """Per source run (BSN, BSN-D) of ``seed``: its IoU on the table's test clips of ``style`` as the
    table recorded it and as scored here, and whether they agree (to the table's four places): the
    arms stand on the table's own run, or on one trained again by its recipe."""
    out = {}
    for label in ("BSN", "BSN-D"):
        rec = ledger.get(run_key(label, style, seed))
        table = rec["test"][style]["iou"] if rec else None
        here = scores[label]["table"]["iou"] if "table" in scores[label] else None
        out[label] = {"table": table, "here": None if here is None else round(here, 4),
                      "same_run": None if table is None or here is None else abs(table - round(here, 4)) < 1e-4}
    return out


def earlier(path: Path, family: str, style: str, tests: list[str]) -> dict[str, Any]:
    """The report at ``path`` if it is of the same family, style and test sets (its seeds are kept),
    else nothing."""
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    same = (old.get("family"), old.get("style"), old.get("tests")) == (family, style, tests)
    return old if same and "scores" in old else {}


def teacher_miou(work: Path) -> float | None:
    """The last validation mIoU of the table's teacher in ``work`` (None if it has none)."""
    curve = run_curve(teacher_run(work), "teacher", "val_miou")["val_miou"]
    return curve[-1] if curve else None


def missing_runs(ex: dict[str, Any], work: Path, seeds: list[int], style: str) -> list[tuple[str, int, Path]]:
    """The kept source runs (BSN, BSN-D) of ``seeds`` that are not in ``work``: (label, seed, folder)."""
    runs = [(label, sd, source_run(work, sd, ex["models"][label], style)) for sd in seeds for label in ("BSN", "BSN-D")]
    return [r for r in runs if not Run(r[2]).model_path.is_file()]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_table_arguments(p)
    p.add_argument("--seeds", type=int, nargs="+", default=[1],
                   help="whose kept runs, and the new runs' seeds (default %(default)s)")
    p.add_argument("--style", choices=STYLES, default="town",
                   help="the training style of the runs (default %(default)s)")
    p.add_argument("--retrain", action="store_true",
                   help="train a seed's BSN or BSN-D run again by the table's recipe where its kept run is gone "
                        "(the table's clips and teacher too, where they are gone)")
    args = p.parse_args(argv)
    out, work = Path(args.out), Path(args.work)
    ledger = read_table(out, args.family, "bench_depth_role")
    if ledger is None:
        return 2
    ex = ledger.experiment
    seeds = sorted(set(args.seeds))
    missing = missing_runs(ex, work, seeds, args.style)
    if missing and not args.retrain:
        where = ", ".join(str(r) for *_, r in missing)
        print(f"bench_depth_role: no kept run at {where} (bench_bsn_accuracy trains them; --retrain trains them "
              "again by the table's recipe)")
        return 2
    oracle_name = f"{ex['models']['BSN']}-oracle"
    if oracle_name not in MODELS:
        print(f"bench_depth_role: the registry has no {oracle_name!r} model for the oracle arm")
        return 2
    if missing:
        train, _, teacher = prepare(work, ex)
        if teacher is not None:
            print(f"bench_depth_role: the table's teacher trained again, validation mIoU {teacher['val_miou'][-1]:.3f}")
        for label, sd, run in missing:
            train_run(train, run, source_settings(ex, work, ex["models"][label], args.style, sd))
    tests = {n: d for n, d in {"table": work / "test", "more": work / "test_more"}.items() if d.is_dir()}
    name = f"{report_name(args.family)}_depth_role"
    before = earlier(out / f"{name}.json", args.family, args.style, list(tests))
    kept = [int(sd) for sd in before.get("scores", {}) if int(sd) not in seeds]
    result: dict[str, Any] = {"family": args.family, "style": args.style, "seeds": sorted([*kept, *seeds]),
                              "tests": list(tests), "scores": {}, "val_iou": {}, "source_runs": {},
                              "teacher": {}, "scored": {}}
    for sd in kept:
        for part in ("scores", "val_iou", "source_runs", "teacher"):
            if str(sd) in before.get(part, {}):
                result[part][str(sd)] = before[part][str(sd)]
        result["scored"][str(sd)] = before.get("scored", {}).get(str(sd), before.get("measured_at"))
    for sd in seeds:
        result["scores"][str(sd)], result["val_iou"][str(sd)] = seed_arms(ex, work, sd, args.style, tests, oracle_name)
        result["source_runs"][str(sd)] = source_check(ledger, result["scores"][str(sd)], sd, args.style)
        result["teacher"][str(sd)] = {"table": (ledger.get("teacher") or {}).get("val_miou", [None])[-1],
                                      "here": teacher_miou(work)}
        result["scored"][str(sd)] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    path = write_result(out, name, result, markdown(result, describe_clips(list(tests.values()))))
    print((out / f"{name}.md").read_text())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
