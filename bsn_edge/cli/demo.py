"""``bsn-demo``: the main job on the built-in default, end to end, in one command."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from bsn_edge.cli import run as run_cli
from bsn_edge.cli import sheet, synth
from bsn_edge.cli.common import fail
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.modelfile.trust import TrustPolicy
from bsn_edge.runtime import Engine
from bsn_edge.synth.style import STYLES

PROG = "bsn-demo"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="The main job on the built-in default: render a synthetic town clip, run the shipped int8 "
                    "model on its video with bsn-run, and write the overlay video, the per-frame alert log, a "
                    "CAN log, the summary and a contact sheet of the clip's ground truth.")
    p.add_argument("--out", default="demo", help="output folder (default ./demo)")
    p.add_argument("--frames", type=int, default=150, help="frames of the clip (default 150, 15 s)")
    p.add_argument("--seed", type=int, default=7, help="random seed of the clip (default 7)")
    p.add_argument("--style", default="town", choices=tuple(sorted(STYLES)),
                   help="synthetic world style of the clip (default town)")
    p.add_argument("--model", default=str(DEFAULT_MODEL),
                   help="fused ONNX model (default: the shipped one, signed with the project's key)")
    p.add_argument("--force", action="store_true", help="write into --out even if it holds files already")
    p.add_argument("--allow-unsigned", action="store_true",
                   help="let bsn-run run a --model not signed by a trusted key (see bsn-run --help)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    model = Path(args.model)
    if not model.is_file():
        return fail(PROG, f"model {model} not found; make one with bsn-train and bsn-export (see models/README.md)")
    if out.is_dir() and any(out.iterdir()) and not args.force:
        return fail(PROG, f"{out} holds files already; pass --force to write the demo over them, or --out ANOTHER")
    if out.exists() and not out.is_dir():
        return fail(PROG, f"{out} exists and is not a folder")
    try:                           # verified (seal, signature, graph, self-test) before the clip is rendered
        Engine(model, trust=TrustPolicy.default(allow_unsigned=args.allow_unsigned))
    except (ValueError, OSError) as e:
        return fail(PROG, str(e))
    clip = out / f"{args.style}_{args.seed}"
    rc = synth.main([str(clip), "--frames", str(args.frames), "--style", args.style, "--seed", str(args.seed),
                     "--force"])
    if rc:
        return rc
    rc = sheet.main([str(clip), "--out", str(out / "contact_sheet.png"), "--force"])
    if rc:
        return rc
    summary = out / "summary.json"
    rc = run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--overlay",
                       str(out / "overlay.mp4"), "--log", str(out / "alerts.jsonl"), "--can-log",
                       str(out / "alerts.log"), "--summary", str(summary), "--calib", str(clip / "calibration.json"),
                       "--force", *(["--allow-unsigned"] if args.allow_unsigned else [])])
    if rc:
        return rc
    s = json.loads(summary.read_text())
    print(f"\n{PROG}: {s['frames']} frames at {s['fps']:.1f} frames/s (p99 {s['p99_ms']:.1f} ms) with "
          f"{s['model']['variant']} ({s['model']['quantization']})")
    for name in ("overlay.mp4", "alerts.jsonl", "alerts.log", "summary.json", "contact_sheet.png"):
        print(f"  {out / name}")
    print(f"  decode the CAN log: {_beside_python('bsn-listen')} --can-log {out / 'alerts.log'}")
    return 0


def _beside_python(command: str) -> str:
    """``command`` as the user can type it: the script beside this Python (``.venv/bin/bsn-listen``
    in the README's set-up, relative to the working folder when it lies below it), or its bare name
    when it is not there."""
    script = Path(sys.executable).parent / command
    if not script.exists():
        return command
    try:
        return str(script.relative_to(Path.cwd()))
    except ValueError:
        return str(script)


if __name__ == "__main__":
    raise SystemExit(main())
