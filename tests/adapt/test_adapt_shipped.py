"""bsn-adapt on the shipped default's run as a user gets it from a clone: its own depth head (``bsn:``
labels aligned to the visual odometry's landmarks) and its own teacher, nothing stood in. Judged
against the exact T-frame labels of the same drives, which bsn-adapt never reads; the adapted
model is exported and run as a user would run it.

Slow (labelling and fine-tuning at the default's full size): ``pytest -m slow``.
"""

import json
import shutil
from pathlib import Path

import pytest

from bsn_edge.adapt.finetune import agreement, at_threshold
from bsn_edge.cli import adapt as adapt_cli
from bsn_edge.cli import label as label_cli
from bsn_edge.cli import run as run_cli
from bsn_edge.data import BlindSpotDataset, find_clips
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.train import Run

SHIPPED = Path(__file__).resolve().parents[2] / "models" / "default"
GROUND_TRUTH = ("depth", "semantic", "poses.txt", "bsgt", "boxes", "labels")
DRIVES = (("suburb_a", "suburb", 981), ("town_b", "town", 982))
HORIZON = "2"                                     # seconds: the clips are 8 s long


def iou(run: Path, clips: list) -> dict[str, float]:
    """IoU inside V of ``run`` at its own threshold, against the clips' exact labels."""
    model, card = Run(run).load_model()
    ds = BlindSpotDataset(clips, card.input_size, label_name=f"T{HORIZON}s", camera=card.camera,
                          mounting=card.mounting)
    return at_threshold(agreement(model, ds), card.threshold)


@pytest.mark.slow
def test_adapting_the_shipped_default_with_its_own_labellers_does_not_lose_iou(tmp_path, tests_key):
    assert (SHIPPED / "checkpoint.json").is_file(), f"the shipped run is missing from {SHIPPED}"
    truth, user = tmp_path / "truth", tmp_path / "user"
    for name, style, seed in DRIVES:
        write_clip(SynthConfig(frames=80, fps=10.0, seed=seed, style=style), truth / name)
    assert label_cli.main([*(str(truth / n) for n, _, _ in DRIVES), "--T", HORIZON, "--jobs", "1"]) == 0
    for name, _, _ in DRIVES:                     # the user's copy: frames and the camera file only
        shutil.copytree(truth / name, user / name)
        for gt in GROUND_TRUTH:
            p = user / name / gt
            shutil.rmtree(p) if p.is_dir() else p.unlink(missing_ok=True)

    out = tmp_path / "adapted"
    assert adapt_cli.main(["--run", str(SHIPPED), "--video", *(str(user / n) for n, _, _ in DRIVES),
                           "--out", str(out), "--T", HORIZON, "--steps", "150", "--export", "--sign",
                           str(tests_key), "--quiet"]) == 0
    rep = json.loads((out / "adapt" / "report.json").read_text())
    assert rep["status"] == "ok", rep
    depth_from = {n: c.get("label_depth") for n, c in rep["clips"].items()}
    assert "model" in depth_from.values(), f"no clip was labelled from the depth head: {depth_from}"

    clips = find_clips(truth, f"T{HORIZON}s")
    before, after = iou(SHIPPED, clips), iou(out, clips)
    print(f"IoU against the exact labels: before {before}, after {after}; depth from {depth_from}")
    assert after["iou"] >= before["iou"], (before, after)

    drive = user / DRIVES[0][0]
    summary = tmp_path / "summary.json"
    assert run_cli.main(["--model", str(out / "model_int8.onnx"), "--source", str(drive / "video.mp4"),
                         "--calib", str(drive / "calibration.json"), "--summary", str(summary)]) == 0
    ran = json.loads(summary.read_text())
    assert ran["frames"] == 80 and ran["valid_frames"] == 80, ran
