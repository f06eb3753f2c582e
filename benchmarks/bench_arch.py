"""Architectures (the paper's Table 3): parameters, GMACs, CPU frames/s and, for trained runs, IoU.

    python -m benchmarks.bench_arch --out benchmarks/results [--runs small-light=RUN ...] [--data TEST]

GMACs are counted by ``torch.utils.flop_counter`` at 256x512 for the whole fused model (D and B).
Frames/s: the fused fp32 ONNX model in onnxruntime, 2 intra-op threads, median of ``--repeats``
runs after warm-up, all in one run of this script.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from benchmarks.common import summary, time_calls, write_result
from bsn_edge.export import session, to_onnx
from bsn_edge.models import create_model

ARCHS = ("unet", "small", "small-light", "medium", "large")


def measure(name: str, size: tuple[int, int], repeats: int, workdir: Path) -> dict:
    torch.manual_seed(0)
    m = create_model(name).eval()
    params = sum(p.numel() for p in m.parameters())
    with FlopCounterMode(display=False) as fc, torch.no_grad():
        m(torch.zeros(1, 3, *size))
    gmacs = fc.get_total_flops() / 2e9
    path = to_onnx(m, workdir / f"{name}.onnx", size, {"bsn.model": name})
    sess = session(path, threads=2)
    frame = np.random.default_rng(0).integers(0, 256, (1, *size, 3), dtype=np.uint8)
    med = summary(time_calls(lambda _: sess.run(None, {"frame": frame}), repeats, warmup=5))["median_ms"] / 1e3
    return {"model": name, "params_m": round(params / 1e6, 2), "gmacs": round(gmacs, 2),
            "median_ms": round(1e3 * med, 2), "fps": round(1 / med, 2), "repeats": repeats}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--repeats", type=int, default=30)
    p.add_argument("--runs", nargs="*", default=[], metavar="NAME=RUN", help="trained runs for the IoU column")
    p.add_argument("--data", default=None, help="test clips for the IoU column")
    args = p.parse_args(argv)
    torch.set_num_threads(2)
    size = (256, 512)
    runs = dict(r.split("=", 1) for r in args.runs)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in ARCHS:
            row = measure(name, size, args.repeats, Path(tmp))
            if name in runs and args.data:
                from bsn_edge.cli import eval as eval_cli
                rep_path = Path(tmp) / f"{name}.json"
                eval_cli.main(["--run", runs[name], "--data", args.data, "--out", str(rep_path),
                               "--no-baselines"])
                row["iou"] = round(json.loads(rep_path.read_text())["overall"]["BSN"]["iou"], 4)
            rows.append(row)
            print(row)
    res = {"rows": rows, "size": list(size), "threads": 2}
    lines = ["# Architectures (the paper's Table 3)", "",
             f"Fused D + B at {size[0]}x{size[1]}; frames/s of the fp32 ONNX model in onnxruntime with 2 threads.",
             "", "| model | params (M) | GMACs | ms | frames/s | IoU |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['model']} | {r['params_m']} | {r['gmacs']} | {r['median_ms']} | {r['fps']} | "
                     f"{r.get('iou', '-')} |")
    path = write_result(args.out, "bsn_arch", res, "\n".join(lines))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
