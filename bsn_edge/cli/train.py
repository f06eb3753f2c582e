"""``bsn-train``: train BlindSpotNet on labelled sequence folders."""

from __future__ import annotations

import argparse
import json
import sys

from bsn_edge.cli.common import fail

PROG = "bsn-train"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Train BlindSpotNet (D + B, with the segmentation teacher's distillation) on "
                    "labelled sequence folders. Writes model.pt, checkpoint.json (threshold chosen on "
                    "the validation split, intrinsics, digests) and config.json (resolved) into RUN. "
                    "Runs under torchrun for several processes (DistributedDataParallel).")
    p.add_argument("--config", default=None,
                   help="TOML config: configs/toy.toml (minutes, shows every step works), quick.toml (about 20 "
                        "minutes), campaign.toml (the default's recipe, hours in pieces), smoke.toml (the tests')")
    p.add_argument("--data", required=True, help="folder of labelled sequence folders")
    p.add_argument("--out", required=True, help="run folder")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value, e.g. --set train.steps=100 --set model.name=small")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out from its last checkpoint (verified; the data stream goes on "
                        "where it stopped, so the result is the uninterrupted run's)")
    p.add_argument("--force", action="store_true",
                   help="start again in an --out that already holds a run (its checkpoint, state and teacher go)")
    p.add_argument("--stop-after", type=float, default=None, metavar="MINUTES",
                   help="end this piece of a long training after MINUTES, with a checkpoint; run the same "
                        "command with --resume to go on (the learning-rate schedule spans train.steps, "
                        "whatever the pieces)")
    p.add_argument("--teacher-only", action="store_true",
                   help="train the segmentation teacher alone (teacher.*; RUN/teacher/teacher.pt) and stop, for "
                        "later runs to distil from with --set teacher.checkpoint=RUN; --resume goes on from its "
                        "last state")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # training's modules (torch) after the command line: --help needs none of them
    from bsn_edge.train.config import load_config
    from bsn_edge.train.teacher_training import train_teacher_alone
    from bsn_edge.train.trainer import train

    try:
        cfg = load_config(args.config, args.overrides)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    if args.stop_after is not None and not args.stop_after > 0:
        return fail(PROG, f"--stop-after must be a positive number of minutes, got {args.stop_after:g}")
    if args.teacher_only and args.stop_after is not None:
        return fail(PROG, "--stop-after ends a student's piece; a teacher trained alone stops when killed and goes "
                          "on with --resume from its last state (every teacher.checkpoint_every steps)")
    try:
        if args.teacher_only:
            summary = train_teacher_alone(cfg, args.data, args.out, resume=args.resume, progress=not args.quiet,
                                          force=args.force)
        else:
            summary = train(cfg, args.data, args.out, resume=args.resume, progress=not args.quiet, force=args.force,
                            stop_after=None if args.stop_after is None else args.stop_after * 60.0)
    except (FileNotFoundError, ValueError) as e:
        return fail(PROG, str(e))
    for line in summary.get("skipped_clips", []):
        print(f"{PROG}: skipped {line}", file=sys.stderr)
    for path in summary.get("removed_torn_writes", []):
        print(f"{PROG}: removed {path}, left by a save that was stopped part-way (the last whole save stands)",
              file=sys.stderr)
    print(json.dumps({k: v for k, v in summary.items() if k != "final_loss"}, indent=1))
    if "stopped_at" in summary:
        print(f"{PROG}: stopped at step {summary['stopped_at']} of {summary['steps']} (--stop-after); the same "
              "command with --resume goes on from there", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
