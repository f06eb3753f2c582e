"""End-to-end latency profile of the edge loop against the model alone, in one run.

    python -m benchmarks.bench_runtime --model MODEL.onnx --source VIDEO --out benchmarks/results

End to end: ``bsn-run``'s loop on the clip (decode, warp into the model camera, inference,
sectors, smoothing, alert state, CAN encoding and sending on a virtual bus), 2 intra-op threads,
with the clip's camera file (``--calib``; a synthetic clip's own ``calibration.json`` when the
video sits in its sequence folder). Model only: the
same session on the same frames, back to back. Bar: end to end >= 80 % of model-only frames/s.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchmarks.common import summary, time_calls, write_result
from bsn_edge.alerts.senders import CanSender
from bsn_edge.calibration import Calibration
from bsn_edge.runtime import Engine, open_source, run
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.media import read_video

BAR_SHARE = 0.8


def model_only(engine: Engine, source: str, frames: int, camera: CameraState) -> float:
    batches = [camera.frame_for(f).to_model(f)[None] for f in read_video(source, frames)]
    return summary(time_calls(lambda i: engine.infer(batches[i]), len(batches), warmup=5))["per_second"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", required=True)
    p.add_argument("--source", required=True, help="a video file")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--calib", help="the clip's camera file (default: calibration.json beside the video, if any)")
    args = p.parse_args(argv)
    engine = Engine(args.model, threads=2)
    cam_file = Path(args.calib) if args.calib else Path(args.source).parent / SequenceFolder.CALIBRATION
    calibration = Calibration.read(cam_file) if cam_file.is_file() else None
    with CanSender("virtual", "bsn-bench") as tx:
        summary = run(engine, open_source(args.source), [tx], max_frames=args.frames,
                      camera=CameraState(engine.card, calibration))
    mo = model_only(engine, args.source, args.frames, CameraState(engine.card, calibration))
    share = summary["fps"] / mo
    res = {"model": summary["model"], "frames": summary["frames"], "e2e_fps": summary["fps"],
           "p50_ms": summary["p50_ms"], "p95_ms": summary["p95_ms"], "p99_ms": summary["p99_ms"],
           "stage_ms": summary["stage_ms"], "stage_share": summary["stage_share"], "model_only_fps": mo,
           "e2e_over_model": share, "bar": BAR_SHARE, "passes": share >= BAR_SHARE, "threads": 2}
    md = ["# Edge runtime latency profile", "",
          f"`{summary['model']['variant']}` ({summary['model']['quantization']}) at "
          f"{summary['model']['size'][0]}x{summary['model']['size'][1]}, {summary['frames']} frames, 2 threads, "
          "CAN on a virtual bus.", "",
          "| end to end frames/s | model only frames/s | ratio | p50 ms | p95 ms | p99 ms |",
          "|---|---|---|---|---|---|",
          f"| {summary['fps']:.1f} | {mo:.1f} | {100 * share:.0f} % | {summary['p50_ms']:.1f} | "
          f"{summary['p95_ms']:.1f} | {summary['p99_ms']:.1f} |", "",
          "| stage | ms per frame | share |", "|---|---|---|"]
    md += [f"| {k} | {summary['stage_ms'][k]:.2f} | {100 * v:.1f} % |" for k, v in summary["stage_share"].items()]
    md += ["", f"Bar: end to end >= {100 * BAR_SHARE:.0f} % of model-only frames/s "
           f"({'passes' if res['passes'] else 'FAILS'})."]
    path = write_result(args.out, "runtime", res, "\n".join(md))
    print("\n".join(md))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
