"""Training with the camera a user without a camera file gets: the picture bsn-run would show the
model (a plain resize at start; the focus of expansion in place once calibrated online), labels that
follow the picture through the clip's lens, and batches that mix both cameras by each sample's draw."""

import json

import cv2
import numpy as np
import pytest
import torch

from bsn_edge import semantics as sm
from bsn_edge.calibration.camera_file import Calibration, assumed_camera
from bsn_edge.camera import Intrinsics
from bsn_edge.cli import train as train_cli
from bsn_edge.data import BlindSpotDataset
from bsn_edge.data.cache import SampleCache, dataset_key
from bsn_edge.data.camera_mix import CameraMix
from bsn_edge.data.dataset import Clip
from bsn_edge.data.guessed_camera import ClipCamera, Guess, guess_of, guessed_camera, online_mounting
from bsn_edge.model_frame import ModelFrame
from bsn_edge.mounting import Mounting
from bsn_edge.sequence import read_mask, write_mask
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.frames import read_rgb
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.synth.rig import Rig
from bsn_edge.train.config import load_config
from bsn_edge.train.trainer import depth_weights
from tests.fakes import SMOKE

MODEL = Intrinsics.from_fov(256, 128, 80.0)
REF = Mounting(1.5, pitch_deg=1.5)


def named(guess: Guess, stem: str) -> str:
    """A clip folder name whose draw is ``guess``."""
    return next(f"{stem}{i}" for i in range(100) if guess_of(f"{stem}{i}")[0] is guess)


def clip_with_road_labels(tmp_path, name: str, seed: int) -> Clip:
    """A one-frame clip of rig ``seed`` whose blind-spot label is the road, made in the label camera
    as bsn-label makes labels (the lens taken out of the raw semantics)."""
    out = write_clip(SynthConfig(frames=1, height=192, width=384, seed=seed, parked=0, traffic=0, pedestrians=0),
                     tmp_path / name, video=False)
    seq = SequenceFolder(out)
    cal = Calibration.read(seq.calibration_path)
    road_raw = (cv2.imread(str(seq.semantic(0)), cv2.IMREAD_UNCHANGED) == sm.ROAD).astype(np.uint8)
    k = cal.intrinsics.scaled(384, 192)
    road_label = ModelFrame.undistort_only(k, cal.dist, cal.mounting).labels_to_model(road_raw) \
        if cal.has_distortion else road_raw
    lab = seq.labels("T5s")
    lab.make_dirs()
    write_mask(lab.visibility(0), np.ones((192, 384), bool))
    write_mask(lab.blindspot(0), road_label > 0)
    return Clip(out, "town", (0,))


def test_at_start_the_model_sees_the_raw_picture_resized(tmp_path):
    seed = next(s for s in range(300) if (r := Rig.draw(s)).k1 == 0 and r.hood == 0
                and abs(r.hfov_deg - 80) > 15 and abs(r.pitch_deg - 1.5) > 1)
    clip = clip_with_road_labels(tmp_path, named(Guess.AT_START, "start"), seed)
    item = BlindSpotDataset([clip], (128, 256), camera=MODEL, mounting=REF, clip_camera=ClipCamera.GUESSED).load(0)
    raw = read_rgb(clip.path, 0)
    resized = cv2.resize(raw, (256, 128), interpolation=cv2.INTER_LINEAR)
    assert np.abs(item["rgb"].astype(int) - resized.astype(int)).mean() < 1.0
    label = read_mask(SequenceFolder(clip.path).labels("T5s").blindspot(0)).astype(np.uint8)
    agree = (item["blindspot"] > 0) == (cv2.resize(label, (256, 128), interpolation=cv2.INTER_NEAREST) > 0)
    assert agree.mean() > 0.99
    # the clip's own camera shows another picture (its field of view and pitch are not the model's)
    own = BlindSpotDataset([clip], (128, 256), camera=MODEL, mounting=REF).load(0)
    assert np.abs(own["rgb"].astype(int) - resized.astype(int)).mean() > 10


def test_online_calibration_puts_the_true_focus_of_expansion_on_the_level_axis():
    own = Calibration.of(Intrinsics.from_fov(640, 360, 110.0), (), Mounting(1.3, pitch_deg=4.0, yaw_deg=-3.0))
    assumed = assumed_camera(MODEL, REF, 640, 360).intrinsics
    m = online_mounting(own, assumed)
    forward = own.mounting.rotation() @ [0.0, 0.0, 1.0]
    foe = own.intrinsics.K @ (forward / forward[2])                  # where the true camera sees the car's axis
    level = m.rotation().T @ np.linalg.solve(assumed.K, foe)         # that pixel's ray under the guess
    assert np.degrees(np.arctan2(np.hypot(level[0], level[1]), level[2])) < 1e-6
    assert m.height_m == 1.3 and m.roll_deg == 0.0
    # a wider lens than assumed: the angles that put it there are smaller than the true ones
    assert 0 < m.pitch_deg < 4.0 and -3.0 < m.yaw_deg < 0


def test_midway_guesses_scatter_about_the_converged_mounting():
    own = Calibration.of(Intrinsics.from_fov(640, 360, 60.0), (), Mounting(1.5, pitch_deg=2.0, yaw_deg=1.0))
    assumed = assumed_camera(MODEL, REF, 640, 360)
    converged = online_mounting(own, assumed.intrinsics)
    errs, kinds = [], set()
    for i in range(200):
        cam, kind = guessed_camera(f"clip{i}", own, 640, 360, MODEL, REF)
        kinds.add(kind)
        assert cam.intrinsics == assumed.intrinsics and not cam.has_distortion
        if kind is Guess.MIDWAY:
            errs.append((cam.mounting.pitch_deg - converged.pitch_deg, cam.mounting.yaw_deg - converged.yaw_deg))
        else:
            assert cam.mounting == assumed.mounting
    errs = np.array(errs)
    assert kinds == {Guess.AT_START, Guess.MIDWAY} and 60 < len(errs) < 140
    assert np.all(np.abs(errs.mean(axis=0)) < 0.3) and np.all((errs.std(axis=0) > 0.7) & (errs.std(axis=0) < 1.3))
    assert guessed_camera("clip3", own, 640, 360, MODEL, REF) == guessed_camera("clip3", own, 640, 360, MODEL, REF)


def test_labels_follow_the_picture_through_the_lens(tmp_path):
    seed = next(s for s in range(300) if (r := Rig.draw(s)).k1 < -0.08 and r.hood == 0)
    for guess in Guess:
        clip = clip_with_road_labels(tmp_path, named(guess, f"lens_{guess.name}_"), seed)
        ds = BlindSpotDataset([clip], (128, 256), camera=MODEL, mounting=REF, clip_camera=ClipCamera.GUESSED)
        item = ds.load(0)
        seen = item["visibility"] > 0                       # where the label camera reaches (not the lens's rim)
        road = item["semantic"][seen] == sm.ROAD            # the raw semantics, through the frames' warp
        label = item["blindspot"][seen] > 0                 # the label camera's road, through the labels' path
        off = int((road != label).sum())
        assert seen.mean() > 0.8 and road.sum() > 2000 and off < 0.002 * road.size, (guess, off)
        # read as if the labels were on the raw (distorted) frame, the road's edges would sit elsewhere
        raw_label = read_mask(SequenceFolder(clip.path).labels("T5s").blindspot(0)).astype(np.uint8)
        wrong = ds.warps(clip).frames.labels_to_model(raw_label)[seen] > 0
        assert (road != wrong).sum() >= 10 * max(off, 5), ((road != wrong).sum(), off)


def test_a_guessed_cache_has_a_key_of_its_own(tmp_path):
    seed = next(s for s in range(300) if Rig.draw(s).hood == 0)
    clip = clip_with_road_labels(tmp_path, "keyed", seed)
    own, again, guessed = (BlindSpotDataset([clip], (128, 256), camera=MODEL, mounting=REF, clip_camera=c)
                           for c in (ClipCamera.OWN, ClipCamera.OWN, ClipCamera.GUESSED))
    assert dataset_key(own) == dataset_key(again) != dataset_key(guessed)


@pytest.fixture(scope="module")
def two_caches(tmp_path_factory):
    root = tmp_path_factory.mktemp("mix")
    clips = [clip_with_road_labels(root, f"mix{i}", s) for i, s in enumerate((3, 8, 11))]
    make = [BlindSpotDataset(clips, (128, 256), augment=True, camera=MODEL, mounting=REF, seed=2, clip_camera=c)
            for c in ClipCamera]
    return tuple(SampleCache.for_dataset(ds, None) for ds in make)


def test_a_mixed_batch_takes_each_sample_from_the_cache_its_draw_chose(two_caches):
    own, guessed = two_caches
    picks = [(k % 3, 100 + k) for k in range(24)]
    mix = CameraMix(own, guessed, 0.5)
    use = mix.guessed_picks(picks, seed=2)
    assert 0 < use.sum() < len(picks)
    got = mix.batch(picks, augment=True, seed=2)
    assert got["guessed"].tolist() == use.tolist()
    for r, (p, u) in enumerate(zip(picks, use, strict=True)):
        want = (guessed if u else own).batch([p], augment=True, seed=2)
        for name, v in want.items():
            assert torch.equal(got[name][r], v[0]), (name, r)
    assert torch.equal(CameraMix(own, guessed, 0.0).batch(picks, True, 2)["image"], own.batch(picks, True, 2)["image"])
    assert torch.equal(CameraMix(own, guessed, 1.0).batch(picks, True, 2)["image"],
                       guessed.batch(picks, True, 2)["image"])
    # without augmentation (validation) every sample is the own camera's
    assert torch.equal(mix.batch(picks, False, 2)["image"], own.batch(picks, False, 2)["image"])
    assert not mix.batch(picks, False, 2)["guessed"].any()
    many = CameraMix(own, guessed, 0.3).guessed_picks([(0, d) for d in range(2000)], seed=2)
    assert abs(many.mean() - 0.3) < 0.04


def test_guessed_cameras_need_a_cache_and_a_run_validates_on_both(tmp_path):
    with pytest.raises(ValueError, match=r"guessed_camera.*cache"):
        load_config(SMOKE, ["data.guessed_camera=0.5", 'data.cache="off"'])
    with pytest.raises(ValueError, match="guessed_camera"):
        load_config(SMOKE, ["data.guessed_camera=1.5"])
    with pytest.raises(ValueError, match="metric, scale-free, none"):
        load_config(SMOKE, ['data.guessed_depth="free"'])
    data = tmp_path / "data"
    for i, s in enumerate((3, 8, 11, 14)):
        clip_with_road_labels(data, f"run{i}", s)
    run = tmp_path / "run"
    assert train_cli.main(["--config", SMOKE, "--data", str(data), "--out", str(run), "--quiet",
                           "--set", "data.guessed_camera=0.5", "--set", 'data.guessed_depth="scale-free"',
                           "--set", 'data.cache="memory"',
                           "--set", "data.size=[128, 256]", "--set", "train.steps=2", "--set", "train.eval_every=2",
                           "--set", "data.val_fraction=0.5"]) == 0
    last = [json.loads(x) for x in (run / "history.jsonl").read_text().splitlines()][-1]
    assert {"val_iou", "val_guessed_iou"} <= last.keys()


def test_what_a_guessed_sample_teaches_d_is_chosen_by_the_config():
    sem = torch.zeros(2, 1, 4, 8, dtype=torch.long)
    sem[..., 0, 0] = sm.ROAD_USERS[0]
    b = {"semantic": sem[:, 0], "guessed": torch.tensor([True, False])}
    for name, object_weight in (("metric", 5.0), ("scale-free", 1.0), ("none", 5.0), ("none", 1.0)):
        cfg = load_config(SMOKE, [f'data.guessed_depth="{name}"', f"train.depth_object_weight={object_weight}"])
        weight, free = depth_weights(b, cfg)
        if name == "scale-free":
            assert free.tolist() == [True, False] and weight is None
            continue
        assert free is None
        weight = torch.broadcast_to(weight, sem.shape)
        if name == "metric":
            assert weight[0, 0, 0, 0] == weight[1, 0, 0, 0] == 5.0 and weight[0, 0, 1, 1] == 1.0
        else:   # the guessed sample teaches no depth; the other keeps its weights
            assert float(weight[0].abs().sum()) == 0.0
            assert float(weight[1, 0, 0, 0]) == object_weight and float(weight[1, 0, 1, 1]) == 1.0
