"""``bsn-adapt`` on real drives, as the paper judges adaptation: adapt on the first part of a drive, judge the rest.

    python -m bsn_edge.benchmarks.bench_adapt_real --work W [--drive 0006R0 ...] [--teacher own real] \
        --out benchmarks/results

For each CamVid drive (``0006R0`` is held out of every training run; the others are held out of the shipped
default's, which saw rendered clips only), its labelled frames are split in two halves in time. The first
half is handed to ``bsn-adapt`` as a user has it: a folder of frames at their rate, no camera file, no labels
(``--export``; labels from the run's depth head or, where it does not fit, from the road plane found from the
direction of travel). The second half is never seen by it, and both models run on it as ``bsn-run`` runs a
folder with no camera file (``bench_camvid``'s rule):

- **unadapted**: the shipped int8 model at its card's threshold;
- **adapted**: ``bsn-adapt``'s int8 export, at its own threshold and **at a like flagged area** (the threshold
  that flags as much of the judged half as the unadapted model does), by class, with open road and where the
  flagged pixels fall.

**Label quality**: the T-frame labels ``bsn-adapt`` made on the first half, scored as if they were a model's
masks against CamVid's pixel labels of the same frames: the road users they mark as blind spot, the open road
they mark (it should be none), teacher by teacher (``own``: the run's teacher; ``real``: the real-picture
teacher ``lab/campaign/teacher_real``, which saw the labels of ``0001TP`` and ``0016E5`` in training, so
its rows there are marked as seen). The time of each stage of each adaptation is in the report.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.adapt import AdaptConfig, adapt
from bsn_edge.adapt.pipeline import EXPORT_NAME
from bsn_edge.adapt.workspace import AdaptFolder
from bsn_edge.cli.common import CHECKOUT
from bsn_edge.labels import camvid
from bsn_edge.labels.config import LabelConfig
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.images import read_image

from .bench_camvid import FALLS, infer_drive, like_area_threshold, score_masks, table_row
from .bench_realboxes import frac
from .common import load_engine
from .real_samples import REAL, licence
from .runner import Report, run

TEACHERS = {"own": None, "real": CHECKOUT / "lab" / "campaign" / "teacher_real"}
TEACHER_REAL_SAW = ("0001TP", "0016E5")     # drives whose pixel labels taught teacher_real
RATE, HORIZON_S = 1.0, 5.0                  # CamVid's labelled frames are a second apart: T = 5 label frames


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--work", required=True, help="scratch folder: the halves, the adapted runs (kept: a rerun resumes)")
    p.add_argument("--run", default=str(CHECKOUT / "models" / "default"), help="the run adapted (default: the shipped)")
    p.add_argument("--model", default=None, help="the unadapted int8 model judged (default: the shipped one)")
    p.add_argument("--drive", nargs="+", default=[camvid.HELD_OUT], help="CamVid drives (train split)")
    p.add_argument("--teacher", nargs="+", default=["own", "real"], choices=sorted(TEACHERS))
    p.add_argument("--steps", type=int, default=AdaptConfig.steps, help="fine-tuning steps")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="adapt_real", help="the report's name in --out")
    return p


def halves(drive: camvid.Drive, work: Path) -> tuple[Path, list[camvid.CamVidFrame], list[camvid.CamVidFrame]]:
    """The drive's first half as a folder of its pictures (what a user hands ``bsn-adapt``), both halves' frames."""
    half = len(drive.frames) // 2
    first, second = list(drive.frames[:half]), list(drive.frames[half:])
    folder = work / f"{drive.name}_first"
    if not folder.is_dir() or len(list(folder.glob("*.jpg"))) != len(first):
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        for fr in first:
            shutil.copy(fr.image, folder / fr.image.name)
    return folder, first, second


def label_quality(out: Path, first: list[camvid.CamVidFrame]) -> dict[str, Any] | None:
    """``bsn-adapt``'s T-frame labels of the first half scored against CamVid's pixel labels as a model's masks
    would be (inside V and out); None when the clip was not labelled."""
    clips = sorted(AdaptFolder(out).clips_dir.iterdir()) if AdaptFolder(out).clips_dir.is_dir() else []
    if not clips:
        return None
    labels = SequenceFolder(clips[0]).labels(f"T{HORIZON_S:g}s")
    frames = labels.frames()
    masks = [(read_image(labels.blindspot(i), cv2.IMREAD_GRAYSCALE) > 0).astype(np.float32) for i in frames]
    vis = [read_image(labels.visibility(i), cv2.IMREAD_GRAYSCALE) > 0 for i in frames]
    truth = [first[i].camvid_label() for i in frames]
    r = score_masks(masks, truth, 0.5)
    return {**r, "label_frames": len(frames), "v_share": round(float(np.mean([v.mean() for v in vis])), 4)}


def adapt_half(args: argparse.Namespace, folder: Path, out: Path, teacher: Path | None) -> dict[str, Any]:
    """``bsn-adapt --export`` on the first half (resumed when ``out`` holds it already); its report."""
    cfg = AdaptConfig(labels=LabelConfig(rate=RATE, horizon_s=HORIZON_S, look_tol=AdaptConfig().labels.look_tol),
                      steps=args.steps)
    resume = AdaptFolder(out).exists()
    return adapt(args.run, [folder], out, cfg, fps=RATE, export=True, resume=resume, force=not resume,
                 progress=False, teacher=teacher)


def judge(model: str, adapted: Path, second: list[camvid.CamVidFrame]) -> dict[str, Any]:
    """Both models on the judged half: the unadapted at its threshold, the adapted at its own and at the
    unadapted's flagged area."""
    labels = [fr.camvid_label() for fr in second]
    base = load_engine(model)
    probs, _ = infer_drive(base, second)
    before = score_masks(probs, labels, base.threshold)
    engine = load_engine(str(adapted))
    probs, _ = infer_drive(engine, second)
    own = score_masks(probs, labels, engine.threshold)
    like = score_masks(probs, labels, like_area_threshold(probs, before["flagged"]))
    return {"unadapted": before, "adapted": own, "adapted_like_area": like}


def _near(r: dict[str, Any]) -> int:
    c = r["counts"]
    return c["vehicles_near"][0] + c["people_near"][0]


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    from bsn_edge.default_model import DEFAULT_MODEL

    root = REAL / "camvid"
    if not root.is_dir():
        print(f"no CamVid frames at {root}: nothing to adapt on")
        return None
    work = Path(args.work)
    model = args.model or str(DEFAULT_MODEL)
    by_name = {d.name: d for d in camvid.drives(root) if d.split == "train"}
    unknown = [d for d in args.drive if d not in by_name]
    if unknown:
        p.error(f"no drive {', '.join(unknown)} in {root}/train (there: {', '.join(sorted(by_name))})")
    head = ["| model (threshold) | near cars | near people and cyclists | all road users | open road flagged | "
            f"frame flagged | flagged on {' / '.join(FALLS)} (%) |", "|---|---|---|---|---|---|---|"]
    result: dict[str, Any] = {"run": args.run, "model": model, "steps": args.steps, "drives": {}}
    md = ["# bsn-adapt on real drives: adapt on the first half, judge the second", "", __doc__.split("\n\n", 2)[2]
          .split("\n\n**Label")[0].strip(), ""]
    quality = ["| drive, teacher | label frames | V of the frame | near cars | near people and cyclists | "
               f"all road users | open road labelled | labelled on {' / '.join(FALLS)} (%) |",
               "|---|---|---|---|---|---|---|---|"]
    stages = ["| drive, teacher | frames | " + " | ".join(("import", "label models", "label", "fine-tune", "export"))
              + " | total (s) |", "|---|---|---|---|---|---|---|---|"]
    for name in args.drive:
        folder, first, second = halves(by_name[name], work)
        rows = [*head]
        base_row = None
        for t in args.teacher:
            out = work / f"adapted_{name}_{t}"
            rep = adapt_half(args, folder, out, TEACHERS[t])
            q = label_quality(out, first)
            j = judge(model, out / EXPORT_NAME, second)
            gain = (_near(j["adapted_like_area"]) - _near(j["unadapted"])) / max(_near(j["unadapted"]), 1)
            seen = " (seen in training)" if t == "real" and name in TEACHER_REAL_SAW else ""
            result["drives"].setdefault(name, {})[t] = {
                "first_half": len(first), "judged_half": len(second), "report": _slim(rep), "label_quality": q,
                "judged": j, "near_gain_like_area": round(gain, 3), "teacher_saw_drive": bool(seen)}
            if base_row is None:
                base_row = table_row("unadapted", j["unadapted"])
                rows.append(base_row)
            kept = " (kept the source)" if "kept_source" in rep else ""
            rows += [table_row(f"adapted, {t} teacher{seen}{kept}", j["adapted"]),
                     table_row(f"adapted, {t} teacher, at the unadapted's flagged area", j["adapted_like_area"])]
            if q is not None:
                c = q["counts"]
                quality.append(f"| {name}, {t}{seen} | {q['label_frames']} | {100 * q['v_share']:.0f} % | "
                               f"{frac(c['vehicles_near'])} | {frac(c['people_near'])} | {frac(c['road_users_all'])} "
                               f"| {100 * q['open_road_flagged']:.1f} % | "
                               + " / ".join(f"{100 * q['falls'][k]:.0f}" for k in FALLS) + " |")
            s = rep.get("stages_s", {})
            stages.append(f"| {name}, {t} | {len(first)} | " + " | ".join(str(s.get(k, "-")) for k in
                          ("import", "label models", "label", "fine-tune", "export")) + f" | {rep.get('seconds')} |")
        md += [f"## {name}: adapted on frames 1-{len(first)}, judged on {len(first) + 1}-{len(first) + len(second)}",
               "", *rows, ""]
    md += ["## Label quality: bsn-adapt's labels of the first halves against CamVid's pixel labels", "", *quality, "",
           "## Time per stage (seconds, this machine)", "", *stages, "", f"Frames and labels: {licence('camvid')}."]
    return Report(result, md, md[4:])


def _slim(rep: dict[str, Any]) -> dict[str, Any]:
    return {k: rep[k] for k in ("clips", "rejected", "agreement", "kept_source", "split", "stages_s", "seconds",
                                "export") if k in rep}


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
