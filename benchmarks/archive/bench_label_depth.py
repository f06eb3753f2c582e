"""Label depth on real frames against LiDAR: the road plane (``--depth ground``) vs the depth head.

    python -m benchmarks.archive.bench_label_depth --run RUN --out benchmarks/results

``bsn-adapt`` labels a user's clips with the run's depth head, or, where that does not fit the
landmarks, with depth from the road plane of the camera's mounting and the run's teacher
segmentation (``ground``). This measures both on the DDAD frames of ``../shared/data/real/``
(mounting from their extrinsics and the LiDAR road plane, as ``bench_realcam``): AbsRel, median
ratio and delta < 1.25 per distance bin, for road and object points, plus how the teacher classes
the LiDAR object points (a thing the teacher calls road gets the road's depth behind it). ``RUN``
must hold its teacher (``bsn-train`` keeps it).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.adapt.labeller import export_teacher
from bsn_edge.export.pipeline import export_run
from bsn_edge.labels.sources.ground_depth import ground_depth
from bsn_edge.labels.sources.onnx_model import OnnxImageModel
from bsn_edge.runtime.engine import Engine
from bsn_edge.train import Run

from ..bench_realcam import ddad_samples, metrics, predict
from ..common import write_result


def teacher_in_raw(teacher: OnnxImageModel, image_bgr: np.ndarray, mf) -> np.ndarray:
    """The teacher's trainIds on the raw frame: it sees the frame in the model camera (as it was
    trained), its classes go back to the raw pixels; pixels the model camera misses are ignored."""
    seg = teacher(cv2.cvtColor(mf.to_model(image_bgr), cv2.COLOR_BGR2RGB)).argmax(0).astype(np.uint8)
    raw = mf.to_raw(seg + 1, cv2.INTER_NEAREST).astype(np.int16) - 1     # 0 = not reached
    return np.where(raw < 0, sm.IGNORE, raw).astype(np.uint8)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="a trained run with its teacher")
    p.add_argument("--out", default="benchmarks/results")
    args = p.parse_args(argv)
    samples = ddad_samples()
    if not samples:
        raise SystemExit("no DDAD frames in ../shared/data/real/ddad_dgp (see its README)")
    run = Run(args.run)
    with tempfile.TemporaryDirectory() as tmp:
        teacher = OnnxImageModel(str(export_teacher(run, Path(tmp) / "teacher.onnx")))
        model = Path(tmp) / "model.onnx"
        export_run(args.run, model, int8=False)
        engine = Engine(str(model))
        card = engine.card
        preds: dict[str, list[np.ndarray]] = {"ground (teacher + mounting)": [], "depth head": []}
        truth, kinds, classes = [], [], []
        for s in samples:
            mf = s.camera.model_frame(s.image.shape[1], s.image.shape[0], card.camera, card.mounting)
            seg = teacher_in_raw(teacher, s.image, mf)
            g = ground_depth(seg, s.camera.intrinsics, s.camera.mounting)
            u, v = np.rint(s.uv[:, 0]).astype(int), np.rint(s.uv[:, 1]).astype(int)
            preds["ground (teacher + mounting)"].append(np.nan_to_num(g[v, u]))
            preds["depth head"].append(predict(engine, s, "camera")[0])
            truth.append(s.z)
            kinds.append(s.kind)
            classes.append(seg[v, u])
    z, kind, cls = np.concatenate(truth), np.concatenate(kinds), np.concatenate(classes)
    result: dict[str, Any] = {"run": str(args.run), "frames": [s.name for s in samples], "rows": {}}
    lines = ["# Label depth on real frames (DDAD, LiDAR): the road plane vs the depth head", "",
             f"Run: `{args.run}` ({card.variant}). {len(samples)} DDAD frames; mounting from their extrinsics and "
             "the LiDAR road plane. Cells: median ratio (prediction / LiDAR) / AbsRel / delta < 1.25 (points); "
             "coverage = share of the LiDAR points the source gives a depth.", "",
             "| source | points | coverage | 5-10 m | 10-20 m | 20-40 m | 5-40 m |", "|---|---|---|---|---|---|---|"]
    for name, parts in preds.items():
        pred = np.concatenate(parts)
        for k in ("road", "object"):
            sel = kind == k
            m = metrics(pred[sel], z[sel])
            cover = float((pred[sel] > 0).mean())
            result["rows"][f"{name} / {k}"] = {"coverage": cover, "bins": m}
            cells = [f"{m[b]['median_ratio']:.2f} / {m[b]['abs_rel']:.3f} / {m[b]['delta_1.25']:.2f} ({m[b]['n']})"
                     if b in m else "-" for b in ("5-10", "10-20", "20-40", "5-40")]
            lines.append(f"| {name} | {k} | {cover:.2f} | " + " | ".join(cells) + " |")
    obj = kind == "object"
    seen = {sm.NAMES[c] if c < sm.NUM_CLASSES else "none": int((cls[obj] == c).sum()) for c in np.unique(cls[obj])}
    near = obj & (z < 10)
    near_road = float(np.isin(cls[near], (sm.ROAD, sm.SIDEWALK)).mean()) if near.any() else float("nan")
    result["teacher_on_objects"] = seen
    result["teacher_road_share_on_objects_within_10m"] = near_road
    lines += ["", "The teacher's classes on the LiDAR object points: "
              + ", ".join(f"{k} {v}" for k, v in sorted(seen.items(), key=lambda x: -x[1]))
              + f". Within 10 m, {100 * near_road:.0f} % of them are called road or sidewalk."]
    write_result(args.out, "label_depth", result, "\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
