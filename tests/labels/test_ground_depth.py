"""Depth from the road plane and the mounting, checked against trigonometry and the renderer's
ray-cast depth (an independent computation of the same scene)."""

import math
import shutil

import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.calibration import Calibration
from bsn_edge.camera import Intrinsics, look_pose
from bsn_edge.labels import LabelConfig, Sources, label_sequence
from bsn_edge.labels.sources.base import ClipRejectedError
from bsn_edge.labels.sources.ground_depth import ground_depth
from bsn_edge.mounting import Mounting
from bsn_edge.sequence import read_mask
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.synth import Boxes, Renderer, SynthConfig, write_clip
from bsn_edge.synth.boxes import KIND_VEHICLE
from tests.fakes import world_with


def test_road_depth_matches_trigonometry():
    cam = Intrinsics.from_fov(256, 128, 80.0)
    h, pitch = 1.4, 2.5
    d = ground_depth(np.full((128, 256), sm.ROAD, np.uint8), cam, Mounting(h, pitch))
    col = int(cam.cx)       # the principal column: the ray stays in the vertical plane
    for row in (80, 100, 127):
        alpha = math.atan((row - cam.cy) / cam.fy)            # below the optical axis
        along = h / math.tan(math.radians(pitch) + alpha)       # ground distance to the point
        z = math.hypot(along, h) * math.cos(alpha)              # its distance along the optical axis
        assert d[row, col] == pytest.approx(z, rel=1e-4)
    horizon = Mounting(h, pitch).horizon_row(cam)
    assert np.isnan(d[: int(horizon) - 1]).all(), "no ground depth at or above the horizon"


def _pose(m: Mounting) -> np.ndarray:
    """Camera-to-world of a car at (1.6, 0) heading +y, its camera mounted as ``m``."""
    T = look_pose(np.array([1.6, 0.0, m.height_m]), np.pi / 2, 0.0)   # the level frame
    T[:3, :3] = T[:3, :3] @ m.rotation().T
    return T


@pytest.mark.parametrize("m", [Mounting(1.5, 1.0), Mounting(1.25, -1.5, 4.0, 2.0), Mounting(1.8, 4.0, -3.0, -2.5)])
def test_rendered_scene_road_and_grounded_things(straight_road, m):
    cam = Intrinsics.from_fov(256, 128, 80.0)
    boxes = Boxes.make([(0.7, 14.0, 0.0), (-4.5, 22.0, 0.0)], [(2.5, 18.5, 1.5), (-2.7, 26.5, 1.6)],
                       sm.CAR, KIND_VEHICLE, (0.5, 0.5, 0.5))
    fr = Renderer(cam).render(world_with(straight_road, boxes), _pose(m))
    d = ground_depth(fr.semantic, cam, m)
    road = sm.is_traversable(fr.semantic) & (fr.depth > 0) & (fr.depth < 60)
    assert road.sum() > 2000
    np.testing.assert_allclose(d[road], fr.depth[road], rtol=2e-3)
    things = (fr.semantic == sm.CAR) & np.isfinite(d)
    assert things.sum() > 200
    ratio = d[things] / fr.depth[things]
    assert np.median(np.abs(ratio - 1)) < 0.03
    assert (fr.semantic == sm.SKY).any() and np.isnan(d[fr.semantic == sm.SKY]).all()


def test_a_thing_whose_contact_is_hidden_has_no_depth(straight_road):
    cam = Intrinsics.from_fov(256, 128, 80.0)
    m = Mounting(1.5, 1.0)
    boxes = Boxes.make([(0.7, 10.0, 0.0), (-8.0, 30.0, 0.0)], [(2.5, 14.5, 1.5), (8.0, 31.0, 10.0)],
                       [sm.CAR, sm.BUILDING], KIND_VEHICLE, (0.5, 0.5, 0.5))
    fr = Renderer(cam).render(world_with(straight_road, boxes), _pose(m))
    d = ground_depth(fr.semantic, cam, m)
    wall_px = fr.semantic == sm.BUILDING
    cols_over_car = np.unique(np.nonzero(fr.semantic == sm.CAR)[1])
    above_car = wall_px.copy()
    above_car[:, np.setdiff1d(np.arange(cam.width), cols_over_car)] = False
    assert above_car.sum() > 50 and np.isnan(d[above_car]).all(), "the wall's contact is hidden by the car"
    seen = wall_px & np.isfinite(d)
    assert seen.sum() > 50
    # a contact is found to the pixel: within half a row, which spans z^2 / (h f) metres of road
    half_row = fr.depth[seen] ** 2 / (2 * m.height_m * cam.fy)
    assert (np.abs(d[seen] - fr.depth[seen]) <= 1.1 * half_row).all()


@pytest.fixture(scope="module")
def synth_clip(tmp_path_factory):
    out = tmp_path_factory.mktemp("ground") / "town"
    write_clip(SynthConfig(frames=30, height=64, width=128, fps=10.0, seed=2), out, video=False)
    return out


def _iou_in_v(exact, other, cfg: LabelConfig) -> float:
    """Blind-spot IoU of ``other``'s labels against ``exact``'s, inside both V (0 without any true one)."""
    a, b = SequenceFolder(exact).labels(cfg.name), SequenceFolder(other).labels(cfg.name)
    tp = fp = fn = 0
    for i in a.frames():
        e, g = read_mask(a.blindspot(i)), read_mask(b.blindspot(i))
        v = read_mask(a.visibility(i)) & read_mask(b.visibility(i))
        tp, fp, fn = tp + (e & g & v).sum(), fp + (g & ~e & v).sum(), fn + (e & ~g & v).sum()
    return tp / (tp + fp + fn) if tp else 0.0


def test_ground_labels_agree_with_exact_labels(synth_clip, tmp_path):
    cfg = LabelConfig(rate=5.0, horizon_s=1.0, min_corr=0.5)
    exact = tmp_path / "exact"
    shutil.copytree(synth_clip, exact)
    label_sequence(exact, cfg)
    ground = tmp_path / "ground"
    shutil.copytree(synth_clip, ground)
    rep = label_sequence(ground, cfg, Sources(depth="ground"))
    assert rep["sources_detail"]["depth"]["kind"] == "ground"
    assert _iou_in_v(exact, ground, cfg) > 0.7


def test_ground_depth_needs_a_mounting(synth_clip, tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(synth_clip, seq)
    path = SequenceFolder(seq).calibration_path
    cal = Calibration.read(path)
    Calibration.of(cal.intrinsics, cal.dist, method="chessboard only").write(path)
    with pytest.raises(ClipRejectedError, match="mounting"):
        label_sequence(seq, LabelConfig(rate=5.0, horizon_s=1.0), Sources(depth="ground"))


@pytest.fixture(scope="module")
def sparse_clip(tmp_path_factory):
    out = tmp_path_factory.mktemp("ground") / "town_sparse"
    write_clip(SynthConfig(frames=40, height=256, width=512, fps=10.0, camera="fixed", seed=2), out, video=False)
    return out


def test_far_apart_frames_without_a_mounting_give_the_exact_labels(sparse_clip, tmp_path):
    """Labelled drives at 1-2 frames/s with no camera mounting (CamVid's): features on things that stay put,
    the road plane found square to the direction of travel, each step scaled by the plane."""
    cfg = LabelConfig(rate=2.0, horizon_s=1.0)
    exact = tmp_path / "exact"
    shutil.copytree(sparse_clip, exact)
    label_sequence(exact, cfg)
    ground = tmp_path / "ground"
    shutil.copytree(sparse_clip, ground)
    path = SequenceFolder(ground).calibration_path
    truth = Calibration.read(path)
    Calibration.of(truth.intrinsics, truth.dist).write(path)
    rep = label_sequence(ground, cfg, Sources(depth="ground", poses="vo"))
    depth, poses = rep["sources_detail"]["depth"], rep["sources_detail"]["poses"]
    assert poses["matched_by"] == "features" and depth["mounting_from"] == "direction of travel"
    assert depth["mounting"]["pitch_deg"] == pytest.approx(truth.mounting.pitch_deg, abs=0.5)
    assert _iou_in_v(exact, ground, cfg) > 0.7
