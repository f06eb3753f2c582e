"""Does one clip of the missing kind close the gap? A controlled check of Table 2's suburb collapse.

    python -m benchmarks.archive.bench_coverage --family shared-light --out benchmarks/results \
        --work ~/.cache/bsn-edge/accuracy [--key BSN/suburb/seed1] [--steps 600]

:mod:`benchmarks.archive.bench_bsn_rescore` found the suburb-trained runs of Table 2 failing on wide-angle
night clips, which suburb's training clips do not include. If that gap is the cause, training on one
such clip should close it, and training on another clip of a kind suburb already has should not.

One kept suburb-trained run (``--key``) is fine-tuned three times, same steps, learning rate and
seed, on suburb's training clips plus: nothing (more steps alone), one wide-angle day clip (one
more clip alone), one wide-angle night clip. The added clips are new suburb worlds, found as the
first seeds from 2000 whose drawn camera is at least ``--min-hfov`` wide. All four models are scored
per clip, at their own thresholds and by average precision, on the suburb test clips of the table
and of the rescore (run ``bench_bsn_rescore`` first for those).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from bsn_edge.cli import label as label_cli
from bsn_edge.data import find_clips, split_clips
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.synth.clip import build_scenario
from bsn_edge.synth.rig import Rig
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
    FINETUNE_LR,
    report_name,
    shared_settings,
    source_run,
    teacher_settings,
    trained_keys,
)
from ..common import records, train_run, write_result

STYLE = "suburb"
ARMS = ("nothing", "day", "night")       # what the fine-tuning adds to suburb's training clips
DAY = ("sun", "overcast")


def find_world(kind: str, min_hfov: float, frames: int, size: tuple[int, int], start: int = 2000) -> int:
    """The first seed from ``start`` whose suburb world has ``kind`` light ("day": sun or overcast;
    "night") and a drawn camera at least ``min_hfov`` degrees wide."""
    for seed in range(start, start + 2000):
        if Rig.draw(seed).hfov_deg < min_hfov:
            continue
        light = build_scenario(SynthConfig(frames=frames, style=STYLE, seed=seed, height=size[0],
                                           width=size[1])).world.look.light
        if light in (("night",) if kind == "night" else DAY):
            return seed
    raise RuntimeError(f"no {kind} suburb world with a camera of {min_hfov} degrees or more in 2000 seeds")


def arm_data(work: Path, arm: str, added: Path | None) -> Path:
    """A folder of links to suburb's training clips, plus ``added``; the added clip must land in the
    training part of the split, not in validation."""
    root = work / "coverage" / f"data_{arm}"
    root.mkdir(parents=True, exist_ok=True)
    for seq in [*sorted((work / "train").glob(f"{STYLE}_*")), *([added] if added else [])]:
        link = root / seq.name
        if not link.exists():
            link.symlink_to(seq.resolve(), target_is_directory=True)
    if added is not None:
        split = split_clips(find_clips(root), 0.25, 0.0)
        if added.name not in {c.path.name for c in split["train"]}:
            raise RuntimeError(f"{added.name} falls into validation: rename it")
    return root


def markdown(result: dict[str, Any], described: dict[str, str]) -> str:
    arms = ["before", *ARMS]
    heads = {"before": "before", "nothing": "+ nothing", "day": f"+ wide day ({result['added']['day']})",
             "night": f"+ wide night ({result['added']['night']})"}
    lines = [f"# Does one clip of the missing kind close the gap? ({result['key']})", "",
             f"`{result['key']}` fine-tuned {result['steps']} steps at lr {result['lr']:g} on suburb's training "
             "clips plus nothing, one wide-angle day clip, or one wide-angle night clip (same seed), scored on "
             "the suburb test clips at each model's own threshold: IoU / average precision.", ""]
    lines += arms_by_clip(result["scores"], {a: heads[a] for a in arms}, described)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_table_arguments(p)
    p.add_argument("--key", default=None, help="the suburb-trained run to fine-tune, as its ledger key "
                                               "(default: the first kept BSN one)")
    p.add_argument("--steps", type=int, default=600, help="fine-tuning steps per arm (default %(default)s)")
    p.add_argument("--min-hfov", type=float, default=85.0,
                   help="how wide the added clips' cameras are at least, degrees (default %(default)s)")
    args = p.parse_args(argv)
    out, work = Path(args.out), Path(args.work)
    ledger = read_table(out, args.family, "bench_coverage")
    if ledger is None:
        return 2
    ex = ledger.experiment
    kept = {key: (label, seed, source_run(work, seed, ex["models"][label], src))
            for key, label, src, seed in trained_keys(ledger) if src == STYLE}
    kept = {k: v for k, v in kept.items() if Run(v[2]).model_path.is_file()}
    key = args.key or next((k for k, v in kept.items() if v[0] == "BSN"), None)
    if key not in kept:
        print(f"bench_coverage: no kept suburb-trained run {key or 'of BSN'}; kept: {', '.join(kept) or 'none'}")
        return 2
    label, seed, base = kept[key]
    size, frames = tuple(ex["size"]), ex["frames_per_clip"]
    clips = work / "coverage" / "clips"
    added: dict[str, Path | None] = {"nothing": None}
    for kind in ("day", "night"):
        world = find_world(kind, args.min_hfov, frames, size)
        seq = clips / f"{STYLE}_wide_{kind}"
        if not (seq / "meta.json").exists():
            write_clip(SynthConfig(frames=frames, style=STYLE, seed=world, height=size[0], width=size[1]), seq,
                       video=False)
        added[kind] = seq
    label_cli.main([*map(str, sorted(clips.iterdir())), "--jobs", "2"])
    tests = {"table": work / "test", "more": work / "test_more"}
    tests = {n: d for n, d in tests.items() if d.is_dir()}
    # the run as the table has it, scored where bench_bsn_rescore keeps its scores (read back if there)
    scores: dict[str, Any] = {"before": {n: score(base, d, score_path(work, n, seed, base, STYLE), STYLE)
                                         for n, d in tests.items()}}
    for arm in ARMS:
        run = work / "coverage" / f"{base.name}_seed{seed}_plus_{arm}"
        train_run(arm_data(work, arm, added[arm]), run,
                  [*shared_settings(ex), *teacher_settings(work), f'model.name="{ex["models"][label]}"',
                   f"train.steps={args.steps}", *records(args.steps), f"train.seed={seed}",
                   f'data.train_styles=["{STYLE}"]', f'train.init="{base}"', f"train.lr={FINETUNE_LR}"])
        scores[arm] = {n: score(run, d, work / "coverage" / "scores" / f"{arm}_{n}.json", STYLE)
                       for n, d in tests.items()}
    described = describe_clips([*tests.values(), clips])
    result = {"key": key, "steps": args.steps, "lr": FINETUNE_LR,
              "added": {k: (described.get(v.name) if v else None) for k, v in added.items()}, "scores": scores}
    name = f"{report_name(args.family)}_coverage"
    path = write_result(out, name, result, markdown(result, described))
    print((out / f"{name}.md").read_text())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
