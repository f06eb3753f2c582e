"""The sample cache gives what the dataset gives, sample by sample, and the teacher's grid what the teacher gives."""

import numpy as np
import pytest
import torch

from bsn_edge import semantics as sm
from bsn_edge.cli import label as label_cli
from bsn_edge.cli import synth as synth_cli
from bsn_edge.data import BlindSpotDataset, find_clips
from bsn_edge.data.cache import SampleCache, dataset_key
from bsn_edge.data.repaint import SeeThrough
from bsn_edge.networks import create_teacher
from bsn_edge.sequence.images import DEPTH_SCALE
from bsn_edge.train.device import scaled
from bsn_edge.train.losses import pairwise_similarity


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    root = tmp_path_factory.mktemp("cache_data")
    for style, seed in (("town", 4), ("urban", 5)):
        assert synth_cli.main([str(root / f"{style}_{seed}"), "--frames", "24", "--size", "64x128",
                               "--style", style, "--seed", str(seed), "--no-video"]) == 0
    assert label_cli.main([*map(str, sorted(root.iterdir())), "--T", "1", "--jobs", "1"]) == 0
    return find_clips(root, "T1s")


def test_cached_batches_are_the_datasets_samples_with_the_same_augmentation(clips):
    ds = BlindSpotDataset(clips, (64, 128), augment=True, label_name="T1s", seed=7)
    cache = SampleCache.for_dataset(ds, None)
    picks = [(k, 1000 + 3 * k) for k in (5, 0, len(ds) - 1, 2, 5, 9)]   # unsorted, a repeat
    got = cache.batch(picks, augment=True, seed=7)
    flips = 0
    for r, (k, draw) in enumerate(picks):
        want = ds[(k, draw)]
        flips += not torch.equal(want["blindspot"], ds[(k, 0)]["blindspot"])
        torch.testing.assert_close(got["image"][r], want["image"], atol=1e-5, rtol=0)
        torch.testing.assert_close(got["depth"][r], want["depth"], atol=0.5 / DEPTH_SCALE + 1e-6, rtol=0)
        for name in ("semantic", "blindspot", "visibility", "sky"):
            assert torch.equal(got[name][r], want[name]), name
    assert got["image"].shape == (len(picks), 3, 64, 128)
    assert 0 < flips < len(picks) or len(picks) < 4, "the draws flip some samples and not others"


def test_repainted_batches_are_the_datasets_and_touch_only_vehicles_and_people(clips):
    ds = BlindSpotDataset(clips, (64, 128), augment=True, label_name="T1s", seed=7, object_repaint=1.0)
    plain_ds = BlindSpotDataset(clips, (64, 128), augment=True, label_name="T1s", seed=7)
    cache = SampleCache.for_dataset(ds, None)
    picks = [(k, 500 + k) for k in range(0, len(ds), max(1, len(ds) // 6))]
    got = cache.batch(picks, augment=True, seed=7, object_repaint=1.0)
    plain = cache.batch(picks, augment=True, seed=7)
    touched = 0
    for r, (k, draw) in enumerate(picks):
        torch.testing.assert_close(got["image"][r], ds[(k, draw)]["image"], atol=1e-5, rtol=0)
        torch.testing.assert_close(plain["image"][r], plain_ds[(k, draw)]["image"], atol=1e-5, rtol=0)
        obj = torch.isin(got["semantic"][r], torch.tensor(sm.VEHICLES + sm.VULNERABLE))
        assert torch.equal(got["image"][r][:, ~obj], plain["image"][r][:, ~obj])
        touched += int((got["image"][r][:, obj] != plain["image"][r][:, obj]).any())
        for name in ("depth", "semantic", "blindspot", "visibility"):
            assert torch.equal(got[name][r], plain[name][r]), name
    assert touched >= 2, "the synthetic clips have cars: some of them must be repainted"


def test_see_through_batches_are_the_datasets_and_touch_only_vehicles_and_people(clips):
    kw = dict(augment=True, label_name="T1s", seed=3)
    ds = BlindSpotDataset(clips, (64, 128), object_repaint=0.5, object_see_through=1.0, **kw)
    painted_ds = BlindSpotDataset(clips, (64, 128), object_repaint=0.5, **kw)
    cache = SampleCache.for_dataset(ds, None)
    picks = [(k, 700 + k) for k in range(0, len(ds), max(1, len(ds) // 6))]
    got = cache.batch(picks, augment=True, seed=3, object_repaint=0.5, object_see_through=1.0)
    painted = cache.batch(picks, augment=True, seed=3, object_repaint=0.5)
    touched = 0
    for r, (k, draw) in enumerate(picks):
        torch.testing.assert_close(got["image"][r], ds[(k, draw)]["image"], atol=1e-5, rtol=0)
        torch.testing.assert_close(painted["image"][r], painted_ds[(k, draw)]["image"], atol=1e-5, rtol=0)
        obj = torch.isin(got["semantic"][r], torch.tensor(sm.ROAD_USERS))
        assert torch.equal(got["image"][r][:, ~obj], painted["image"][r][:, ~obj])
        touched += int((got["image"][r][:, obj] != painted["image"][r][:, obj]).any())
        for name in ("depth", "semantic", "blindspot", "visibility"):
            assert torch.equal(got[name][r], painted[name][r]), name
    assert touched >= 2, "the synthetic clips have cars: the scene must show through some of them"
    through = SeeThrough((4, 0), 0.5, np.ones((3, 6), np.float32))
    with pytest.raises(ValueError, match="needs the samples' semantics"):
        cache.images(np.array([0]), np.zeros(1, bool), np.ones(1), np.zeros(1), throughs=[through])


def test_camera_look_batches_are_the_datasets_and_leave_the_labels(clips):
    kw = dict(augment=True, label_name="T1s", seed=3)
    ds = BlindSpotDataset(clips, (64, 128), object_repaint=0.5, camera_look=0.7, **kw)
    cache = SampleCache.for_dataset(ds, None)
    picks = [(k, 900 + k) for k in range(0, len(ds), max(1, len(ds) // 6))]
    got = cache.batch(picks, augment=True, seed=3, object_repaint=0.5, camera_look=0.7)
    before = cache.batch(picks, augment=True, seed=3, object_repaint=0.5)
    changed = 0
    for r, (k, draw) in enumerate(picks):
        torch.testing.assert_close(got["image"][r], ds[(k, draw)]["image"], atol=1e-5, rtol=0)
        changed += int(not torch.equal(got["image"][r], before["image"][r]))
        for name in ("depth", "semantic", "blindspot", "visibility"):
            assert torch.equal(got[name][r], before[name][r]), name
    assert changed >= 2, "a share of 0.7 must show some samples through a camera of their own"


def test_a_disk_cache_is_reused_and_a_relabelled_clip_makes_a_new_one(clips, tmp_path):
    ds = BlindSpotDataset(clips[:1], (64, 128), label_name="T1s")
    first = SampleCache.for_dataset(ds, tmp_path)
    again = SampleCache.for_dataset(ds, tmp_path)
    assert again.folder == first.folder and isinstance(again.arrays["rgb"], np.memmap)
    assert np.array_equal(again.arrays["masks"], first.arrays["masks"])
    report = clips[0].path / "labels" / "T1s" / "report.json"
    report.write_text(report.read_text() + "\n")
    assert dataset_key(ds) != first.key, "a changed label report must not reuse the old samples"
    assert not list(tmp_path.glob("*.tmp*")), "no half-built folder is left behind"


def test_the_teacher_grid_is_the_teachers_features_of_the_flipped_or_plain_frame(clips):
    torch.manual_seed(0)
    teacher = create_teacher("resnet18", 32).eval()
    ds = BlindSpotDataset(clips, (64, 128), augment=True, label_name="T1s", seed=2)
    cache = SampleCache.for_dataset(ds, None)
    cache.attach_teacher(teacher, 0.5, (4, 8), resize=scaled)
    picks = [(k, k) for k in range(8)]
    got = cache.batch(picks, augment=True, seed=2)
    plain = cache.batch(picks, augment=False, seed=2)["image"]
    for r, (k, _) in enumerate(picks):
        flipped = not torch.equal(got["blindspot"][r], cache.batch([(k, 0)], False, 0)["blindspot"][0])
        x = plain[r:r + 1].flip(-1) if flipped else plain[r:r + 1]
        with torch.no_grad():
            want = torch.nn.functional.adaptive_avg_pool2d(teacher(scaled(x, 0.5))[1], (4, 8))
        # stored as float16: the similarity matrices the loss compares agree far closer than they vary
        assert torch.allclose(pairwise_similarity(got["teacher_grid"][r:r + 1], (4, 8)),
                              pairwise_similarity(want, (4, 8)), atol=2e-3)


def test_teacher_features_in_bf16_keep_the_similarities_the_loss_compares(clips):
    torch.manual_seed(0)
    teacher = create_teacher("resnet18", 32).eval()
    ds = BlindSpotDataset(clips, (64, 128), label_name="T1s")
    full, half = SampleCache.for_dataset(ds, None), SampleCache.for_dataset(ds, None)
    full.attach_teacher(teacher, 0.5, (4, 8), resize=scaled)
    half.attach_teacher(teacher, 0.5, (4, 8), resize=scaled, dtype=torch.bfloat16)
    picks = [(k, 0) for k in range(8)]
    a = pairwise_similarity(full.batch(picks, False, 0)["teacher_grid"], (4, 8))
    b = pairwise_similarity(half.batch(picks, False, 0)["teacher_grid"], (4, 8))
    assert (a - b).abs().max() < 0.05
