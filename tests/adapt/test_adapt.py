"""bsn-adapt: unlabelled clips in, an adapted run out; nothing reads a clip's ground truth."""

import dataclasses
import json
import shutil

import cv2
import numpy as np
import pytest
import torch

from bsn_edge.adapt import clips as clips_mod
from bsn_edge.adapt import pipeline
from bsn_edge.adapt.config import ADAPT_LABELS
from bsn_edge.adapt.labeller import export_teacher, load_teacher
from bsn_edge.cli import adapt as adapt_cli
from bsn_edge.cli import label as label_cli
from bsn_edge.cli import synth as synth_cli
from bsn_edge.cli import train as train_cli
from bsn_edge.labels.sources.base import SegSource
from bsn_edge.labels.sources.onnx_model import OnnxImageModel
from bsn_edge.sequence import read_depth
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.train import Run
from tests.fakes import SMOKE

T1S = dataclasses.replace(ADAPT_LABELS, horizon_s=1.0)   # labels short enough for a smoke clip

GROUND_TRUTH = ("depth", "semantic", "poses.txt", "bsgt", "boxes")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A smoke-trained run (weights, threshold and teacher): enough to fine-tune, not to label."""
    root = tmp_path_factory.mktemp("adapt_run")
    data = root / "data"
    assert synth_cli.main([str(data / "town_0"), "--frames", "30", "--size", "64x128", "--seed", "0",
                           "--no-video"]) == 0
    assert label_cli.main([str(data / "town_0"), "--T", "2", "--jobs", "1"]) == 0
    assert train_cli.main(["--config", SMOKE, "--data", str(data), "--out", str(root / "run"), "--quiet",
                           "--set", "data.label=T2s"]) == 0
    return root / "run"


@pytest.fixture(scope="module")
def user_clip(tmp_path_factory):
    """A drive as a user would bring it: frames and a camera file only. Its depth and semantics
    are kept elsewhere (``hidden``) for the stand-in label models, then removed from the clip."""
    root = tmp_path_factory.mktemp("adapt_clip")
    seq, hidden = root / "drive", root / "hidden"
    write_clip(SynthConfig(frames=40, height=128, width=256, fps=10.0, camera="fixed", seed=5), seq, video=False)
    (hidden / "rel").mkdir(parents=True)
    shutil.copytree(seq / "semantic", hidden / "semantic")
    for i in range(40):
        d = read_depth(seq / "depth" / f"{i:06d}.png")
        np.save(hidden / "rel" / f"{i:06d}.npy", np.where(d > 0, 9.0 / np.maximum(d, 1e-3), 0) + 0.05)
    for name in GROUND_TRUTH:
        p = seq / name
        shutil.rmtree(p) if p.is_dir() else p.unlink(missing_ok=True)
    return seq, hidden


class HiddenSeg(SegSource):
    """Stand-in for a good segmentation teacher: the clip's own semantics, read from outside it."""

    def __init__(self, folder, clip):
        self.folder, self.clip = folder, clip

    def __call__(self, i):
        return cv2.imread(str(self.folder / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED)


@pytest.fixture
def stand_in_labellers(monkeypatch, user_clip):
    """The smoke run's depth and teacher cannot label anything, so these tests give bsn-adapt
    label models that can: relative depth and semantics written outside the clip. Import, VO,
    labelling, fine-tuning, threshold choice and writing the run are bsn-adapt's own."""
    _, hidden = user_clip
    real_make_seg = pipeline.make_seg

    def make_seg(spec, clip):
        return HiddenSeg(hidden / "semantic", clip) if spec == "hidden" else real_make_seg(spec, clip)

    monkeypatch.setattr(pipeline, "prepare_labeller",
                        lambda src, depth, teacher, labeller=None: {"depth": f"rel:{hidden / 'rel'}:inverse",
                                                                    "seg": "hidden"})
    monkeypatch.setattr(pipeline, "make_seg", make_seg)
    monkeypatch.setattr("bsn_edge.labels.generator.make_seg", make_seg)


def test_adapt_runs_on_a_clip_without_ground_truth(run, user_clip, stand_in_labellers, tmp_path, capsys):
    seq, _ = user_clip
    assert not any((seq / n).exists() for n in GROUND_TRUTH)
    out = tmp_path / "adapted"
    assert adapt_cli.main(["--run", str(run), "--video", str(seq), "--out", str(out), "--T", "1", "--steps", "3",
                           "--quiet"]) == 0
    rep = json.loads((out / "adapt" / "report.json").read_text())
    assert rep["status"] == "ok" and not rep["rejected"], rep["rejected"]
    clip = rep["clips"]["drive"]
    assert clip["label_frames"] > 0 and clip["camera"] == "the clip's camera file"
    assert 0 < clip["blind_spot_share_of_v"] < 1
    imported = out / "adapt" / "clips" / "drive"
    assert not any((imported / n).exists() for n in GROUND_TRUTH)
    label_report = json.loads((imported / "labels" / "T1s" / "report.json").read_text())
    assert label_report["sources_detail"]["poses"]["kind"] == "vo"
    assert clip["label_depth"] == "model" and "model_depth_rejected" not in clip    # the depth fits
    assert label_report["config"]["look_tol"] == 0.0, "the look check is for the road plane's labels"
    a = rep["agreement"]
    assert 0 <= a["before"]["iou"] <= 1 and 0 < a["after"]["threshold"] < 1
    model, card = Run(out).load_model()          # a run like any other: verified weights, its threshold
    assert card.threshold == a["after"]["threshold"] and card.variant == Run(run).card().variant
    old, _ = Run(run).load_model()
    same = [torch.equal(p, q) for p, q in zip(old.depth_net.parameters(), model.depth_net.parameters(), strict=True)]
    assert all(same), "D must stay as trained"
    changed = not all(torch.equal(p, q) for p, q in zip(old.blindspot.parameters(), model.blindspot.parameters(),
                                                         strict=True))
    assert changed == ("kept_source" not in rep), "B is the fine-tuned one unless the source was kept"
    # the card names what it was adapted on, so every export of it does
    assert card.training is not None and "bsn-adapt of run on drive" in card.training.adapted_on, card.training
    assert "agreement with held-out labels" in capsys.readouterr().out

    # the same command again is refused; --resume keeps the labels and fine-tunes again
    assert adapt_cli.main(["--run", str(run), "--video", str(seq), "--out", str(out), "--T", "1", "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err
    labels = imported / "labels" / "T1s" / "blindspot"
    stamp = {p.name: p.stat().st_mtime_ns for p in labels.iterdir()}
    assert adapt_cli.main(["--run", str(run), "--video", str(seq), "--out", str(out), "--T", "1", "--steps", "2",
                           "--seed", "1", "--resume", "--quiet"]) == 0
    assert {p.name: p.stat().st_mtime_ns for p in labels.iterdir()} == stamp
    assert json.loads((out / "adapt" / "report.json").read_text())["fine_tune"]["seed"] == 1


def test_a_fine_tuning_that_lowers_agreement_hands_back_the_source_model(run, user_clip, stand_in_labellers,
                                                                          monkeypatch, tmp_path, capsys):
    seq, _ = user_clip

    def ruin(model, ds, cfg, *args, **kwargs):      # a fine-tuning that leaves B answering "no blind spot"
        with torch.no_grad():
            model.blindspot.head.conv.weight.zero_()
            model.blindspot.head.conv.bias.fill_(-20.0)
        return [1.0]

    monkeypatch.setattr(pipeline, "finetune_b", ruin)
    out = tmp_path / "adapted"
    assert adapt_cli.main(["--run", str(run), "--video", str(seq), "--out", str(out), "--T", "1", "--quiet"]) == 0
    rep = json.loads((out / "adapt" / "report.json").read_text())
    assert rep["fine_tuned_agreement"]["iou"] == 0.0 and "kept_source" in rep
    assert rep["agreement"]["after"]["iou"] == rep["agreement"]["before"]["iou"] > 0
    (kept, card), (source, src_card) = Run(out).load_model(), Run(run).load_model()
    assert all(torch.equal(p, q) for p, q in zip(kept.state_dict().values(), source.state_dict().values(), strict=True))
    assert card.threshold == src_card.threshold
    assert "kept the source model" in capsys.readouterr().out


def test_a_clip_the_depth_head_does_not_fit_is_labelled_from_the_road_plane(run, user_clip, stand_in_labellers,
                                                                            monkeypatch, tmp_path):
    seq, _ = user_clip
    noise = tmp_path / "noise"
    noise.mkdir()
    rng = np.random.default_rng(3)
    for i in range(40):
        np.save(noise / f"{i:06d}.npy", rng.uniform(0.05, 1.0, (128, 256)).astype(np.float32))
    monkeypatch.setattr(pipeline, "prepare_labeller",
                        lambda src, depth, teacher, labeller=None: {"depth": f"rel:{noise}:inverse", "seg": "hidden"})
    out = tmp_path / "adapted"
    rep = pipeline.adapt(run, [seq], out, pipeline.AdaptConfig(labels=T1S, steps=2), progress=False)
    clip = rep["clips"]["drive"]
    assert clip["label_depth"] == "ground" and "depth" in clip["model_depth_rejected"]
    made = json.loads((out / "adapt" / "clips" / "drive" / "labels" / "T1s" / "report.json").read_text())
    assert made["sources_detail"]["depth"]["kind"] == "ground"
    assert made["config"]["look_tol"] == pipeline.AdaptConfig().labels.look_tol > 0
    # resumed, the clip goes straight to the road plane and keeps its label files
    labels = out / "adapt" / "clips" / "drive" / "labels" / "T1s" / "blindspot"
    stamp = {p.name: p.stat().st_mtime_ns for p in labels.iterdir()}
    rep = pipeline.adapt(run, [seq], out, pipeline.AdaptConfig(labels=T1S, steps=2), resume=True, progress=False)
    assert rep["clips"]["drive"]["label_depth"] == "ground"
    assert {p.name: p.stat().st_mtime_ns for p in labels.iterdir()} == stamp


def test_a_camera_without_a_mounting_finds_its_road_plane_from_the_direction_of_travel(run, user_clip,
                                                                                     stand_in_labellers, tmp_path):
    """No refusal for a camera file without a mounting (or none at all): pitch and yaw come from the direction
    the car travels, the height is the model camera's unless stated, and the report says so."""
    from bsn_edge.calibration import Calibration
    from bsn_edge.sequence.folder import SequenceFolder

    seq, _ = user_clip
    truth = Calibration.read(SequenceFolder(seq).calibration_path).mounting
    bare = tmp_path / "bare"
    shutil.copytree(seq, bare)
    cal = Calibration.read(SequenceFolder(bare).calibration_path)
    Calibration.of(cal.intrinsics, cal.dist, method="chessboard only").write(SequenceFolder(bare).calibration_path)
    labels = dataclasses.replace(T1S, camera_height=truth.height_m)
    rep = pipeline.adapt(run, [bare], tmp_path / "o", pipeline.AdaptConfig(labels=labels, steps=2,
                                                                           label_depth="ground"), progress=False)
    clip = rep["clips"]["bare"]
    assert "direction of travel" in clip["road_plane_from"] and "--camera-height" in clip["road_plane_from"]
    made = json.loads((tmp_path / "o" / "adapt" / "clips" / "bare" / "labels" / "T1s" / "report.json").read_text())
    assert made["sources_detail"]["depth"]["mounting_from"] == "direction of travel"
    found = made["sources_detail"]["depth"]["mounting"]
    # the rendered rig's pitch and yaw, found from 4 s of a 256x128 drive alone (the stated height is the rig's;
    # test_vo holds the direction of travel to 0.5 degrees on a longer, sharper drive)
    assert found["pitch_deg"] == pytest.approx(truth.pitch_deg, abs=1.5), (found, truth)
    assert found["yaw_deg"] == pytest.approx(truth.yaw_deg, abs=1.5), (found, truth)


def test_unusable_clips_are_rejected_with_the_reason(run, stand_in_labellers, tmp_path, capsys):
    still = tmp_path / "still"
    still.mkdir()
    frame = np.random.default_rng(0).integers(0, 256, (96, 192, 3), dtype=np.uint8)
    for i in range(30):
        cv2.imwrite(str(still / f"{i:04d}.png"), frame)
    short = tmp_path / "short"
    short.mkdir()
    for i in range(4):
        cv2.imwrite(str(short / f"{i:04d}.png"), frame)
    code = adapt_cli.main(["--run", str(run), "--video", str(still), str(short), str(tmp_path / "nope.mp4"),
                           "--fps", "10", "--out", str(tmp_path / "o"), "--T", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "no clip could be labelled" in err
    assert "standing still" in err and "too short" in err and "nope.mp4: not found" in err
    rep = json.loads((tmp_path / "o" / "adapt" / "report.json").read_text())
    assert rep["status"] == "failed" and set(rep["rejected"]) == {"still", "short", "nope"}
    # a folder of images without a rate is refused before anything is written
    assert adapt_cli.main(["--run", str(run), "--video", str(still), "--out", str(tmp_path / "o2"), "--quiet"]) == 2
    assert "pass --fps" in capsys.readouterr().err


def test_moving_seconds_sees_a_drive_and_not_a_parked_car(user_clip, tmp_path):
    seq, _ = user_clip
    assert clips_mod.moving_seconds(seq, 10.0) > 3.0
    parked = tmp_path / "parked"
    (parked / "rgb").mkdir(parents=True)
    for i in range(20):
        shutil.copy(seq / "rgb" / "000000.png", parked / "rgb" / f"{i:06d}.png")
    assert clips_mod.moving_seconds(parked, 10.0) == 0.0


def test_the_teacher_label_model_matches_the_torch_teacher(run, tmp_path):
    """The teacher exported for labelling gives the torch teacher's classes (a second runtime)."""
    path = export_teacher(Run(run), tmp_path / "teacher.onnx")
    teacher, (h, w), _ = load_teacher(Run(run))
    frame = np.random.default_rng(1).integers(0, 256, (h, w, 3), dtype=np.uint8)
    scores = OnnxImageModel(path)(frame)
    rgb = (frame[..., ::-1].astype(np.float32) / 255.0 - [0.485, 0.456, 0.406]) / [0.229, 0.224, 0.225]
    with torch.no_grad():
        ref = teacher(torch.from_numpy(rgb.transpose(2, 0, 1)[None].astype(np.float32)))[0][0].numpy()
    assert scores.shape == (19, h, w)
    np.testing.assert_allclose(scores, ref, atol=1e-3)


def test_a_clip_whose_labels_hold_no_blind_spot_is_not_trained_on(run, user_clip, stand_in_labellers, tmp_path,
                                                                  monkeypatch, capsys):
    """Fine-tuning on labels with no blind spot would teach B that nothing is ever hidden."""
    seq, _ = user_clip
    monkeypatch.setattr(pipeline, "MIN_BLIND_SPOT_SHARE", 1.01)    # no clip can have more than all of V
    out = tmp_path / "o"
    assert adapt_cli.main(["--run", str(run), "--video", str(seq), "--out", str(out), "--T", "1", "--quiet"]) == 2
    assert "no blind spot in its labels" in capsys.readouterr().err
    assert not Run(out).exists(), "no run may be written from such labels"

