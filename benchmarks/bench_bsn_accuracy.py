"""The paper's Table 2 on held-out synthetic clips: BSN, BSN-D, BSN-KD and the three baselines,
trained on one style, tested on both, with and without fine-tuning on 20 % of the target style.

    python -m benchmarks.bench_bsn_accuracy --out benchmarks/results [--steps 250]

One segmentation teacher is trained on the training clips of both styles (the role an
off-the-shelf segmenter plays in the paper) and shared by every run and by the baselines.
Fine-tuning starts from the source-style run and trains on 20 % of the target style's
training clips. Every run has the same step budget; results are what that budget gives.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from benchmarks.common import eval_run, train_run, write_result
from bsn_edge.cli import label as label_cli
from bsn_edge.synth import SynthConfig, write_clip

MODELS = {"BSN": "small-light", "BSN-D": "small-light-d", "BSN-KD": "small-light-kd"}
STYLES = ("town", "suburb")
BASELINES = ("Traversable", "Detection-2D", "Detection-3D")
FINETUNE_LR = 1e-4  # a tenth of training's: at 1e-3, 20 % of the target style (one clip) erases what was learnt


def make_data(work: Path, train_clips: int, test_clips: int, frames: int) -> tuple[Path, Path]:
    train, test = work / "train", work / "test"
    for style in STYLES:
        for i in range(train_clips + test_clips):
            root = train if i < train_clips else test
            seq = root / f"{style}_{i}"
            if not (seq / "meta.json").exists():
                write_clip(SynthConfig(frames=frames, style=style, seed=1000 + i), seq, video=False)
    for root in (train, test):
        label_cli.main([*map(str, sorted(root.iterdir())), "--jobs", "2"])
    return train, test


def _eval(run: Path, test: Path, style: str, out: Path, baselines: bool) -> dict:
    return eval_run(run, test, out, "--clips", "all", "--styles", style, *(() if baselines else ("--no-baselines",)))


def run(work: Path, steps: int, ft_steps: int, teacher_steps: int, train_clips: int, test_clips: int,
        frames: int) -> dict:
    t0 = time.perf_counter()
    train, test = make_data(work, train_clips, test_clips, frames)
    common = ["data.size=[256, 512]", "data.val_fraction=0.25", "train.batch_size=8",
              f"train.checkpoint_every={steps}"]
    teacher = work / "runs" / "teacher"
    train_run(train, teacher, [*common, "model.name=\"small-light\"", f"teacher.steps={teacher_steps}",
                            "train.steps=1"])
    tsets = [f"teacher.checkpoint=\"{teacher / 'teacher'}\""]
    rows = []
    baseline_done: set[str] = set()
    for label, name in MODELS.items():
        for src in STYLES:
            base = work / "runs" / f"{name}_{src}"
            train_run(train, base, [*common, *tsets, f"model.name=\"{name}\"", f"train.steps={steps}",
                                 f"data.train_styles=[\"{src}\"]"])
            for tgt in STYLES:
                runs = [(False, base)]
                if tgt != src:
                    ft = work / "runs" / f"{name}_{src}_ft_{tgt}"
                    train_run(train, ft, [*common, *tsets, f"model.name=\"{name}\"", f"train.steps={ft_steps}",
                                       f"data.train_styles=[\"{tgt}\"]", "data.fraction=0.2",
                                       f"train.init=\"{base}\"", f"train.lr={FINETUNE_LR}"])
                    runs.append((True, ft))
                for finetune, r in runs:
                    with_base = tgt not in baseline_done
                    rep = _eval(r, test, tgt, work / "eval" / f"{r.name}_on_{tgt}.json", with_base)
                    m = rep["overall"]["BSN"]
                    rows.append({"model": label, "registry": name, "train_style": src, "test_style": tgt,
                                 "finetune": finetune, **{k: round(m[k], 4) for k in ("iou", "recall", "precision")}})
                    if with_base:
                        baseline_done.add(tgt)
                        for b in BASELINES:
                            if b in rep["overall"]:
                                mb = rep["overall"][b]
                                rows.append({"model": b, "registry": None, "train_style": None, "test_style": tgt,
                                             "finetune": False,
                                             **{k: round(mb[k], 4) for k in ("iou", "recall", "precision")}})
    return {"rows": rows, "budget": {"steps": steps, "finetune_steps": ft_steps, "finetune_lr": FINETUNE_LR,
                                     "teacher_steps": teacher_steps,
                                     "batch_size": 8, "size": [256, 512], "device": "CPU, 2 threads"},
            "data": {"train_clips_per_style": train_clips, "test_clips_per_style": test_clips,
                     "frames_per_clip": frames}, "seconds": round(time.perf_counter() - t0)}


def markdown(res: dict) -> str:
    b = res["budget"]
    lines = ["# BlindSpotNet accuracy (the paper's Table 2, synthetic world)", "",
             f"Held-out test clips ({res['data']['test_clips_per_style']} per style), inside V. Each run: "
             f"{b['steps']} steps of batch {b['batch_size']} at {b['size'][0]}x{b['size'][1]} on {b['device']}; "
             f"fine-tuning: {b['finetune_steps']} more steps at lr {b.get('finetune_lr', FINETUNE_LR):g} on 20 % of "
             "the target style's training clips.", "",
             "| model | train | test | fine-tuned | IoU | recall | precision |", "|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['model']} | {r['train_style'] or '-'} | {r['test_style']} | "
                     f"{'yes' if r['finetune'] else 'no'} | {r['iou']:.3f} | {r['recall']:.3f} | "
                     f"{r['precision']:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--work", default="benchmarks/scratch/accuracy", help="clips and runs are kept here")
    p.add_argument("--steps", type=int, default=250)
    p.add_argument("--finetune-steps", type=int, default=80)
    p.add_argument("--teacher-steps", type=int, default=300)
    p.add_argument("--train-clips", type=int, default=5, help="training clips per style")
    p.add_argument("--test-clips", type=int, default=2, help="test clips per style")
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--fresh", action="store_true", help="delete the work folder first")
    args = p.parse_args(argv)
    work = Path(args.work)
    if args.fresh:
        shutil.rmtree(work, ignore_errors=True)
    res = run(work, args.steps, args.finetune_steps, args.teacher_steps, args.train_clips, args.test_clips,
              args.frames)
    path = write_result(args.out, "bsn_accuracy", res, markdown(res))
    print(markdown(res))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
