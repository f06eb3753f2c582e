"""The real-camera benchmark's truth: mounting, road and object points, objects and their distances,
checked on an analytic scene (flat road, box faces at known distances)."""

import math

import numpy as np
import pytest

from bsn_edge.benchmarks.bench_realcam import object_distances
from bsn_edge.benchmarks.real_samples import _ddad_sample
from bsn_edge.camera import Intrinsics

K = Intrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)
HEIGHT = 1.6


def _camera(yaw_deg: float) -> np.ndarray:
    """Camera axes (x right, y down, z forward) in the vehicle frame (x forward, y left, z up)."""
    a = math.radians(yaw_deg)
    fwd = np.array([math.cos(a), math.sin(a), 0.0])
    right = np.array([math.sin(a), -math.cos(a), 0.0])
    return np.stack([right, [0.0, 0.0, -1.0], fwd], 1)


def _face(x: float, y0: float, y1: float) -> np.ndarray:
    """A vertical face at x, 0.5-1.5 m high (a car's back), sampled every 5 cm."""
    y, z = np.meshgrid(np.arange(y0, y1, 0.05), np.arange(0.5, 1.5, 0.05))
    return np.stack([np.full(y.size, x), y.ravel(), z.ravel()], 1)


def _roof(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """A level roof 1.5 m high, sampled every 5 cm."""
    x, y = np.meshgrid(np.arange(x0, x1, 0.05), np.arange(y0, y1, 0.05))
    return np.stack([x.ravel(), y.ravel(), np.full(x.size, 1.5)], 1)


def _scene() -> np.ndarray:
    gx, gy = np.meshgrid(np.arange(-40, 40, 0.25), np.arange(-40, 40, 0.25))
    road = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1)
    # a car's back at 8 m from the camera; a van's back at 20 m with its roof running on to 24 m
    return np.concatenate([road, _face(9.5, -1.0, 1.0), _face(21.5, 3.0, 5.0), _roof(21.5, 25.5, 3.0, 5.0)])


def test_front_camera_mounting_kinds_and_object_distances():
    t_vc = np.array([1.5, 0.0, HEIGHT])
    s = _ddad_sample("analytic", np.zeros((480, 640, 3), np.uint8), K, _camera(0.0), t_vc, _scene())
    m = s.camera.mounting
    assert m.height_m == pytest.approx(HEIGHT, abs=1e-6)
    assert (m.pitch_deg, m.yaw_deg, m.roll_deg) == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
    # road points lie on the plane: their z-depth is height * fy / (v - cy) from the image row
    road = s.kind == "road"
    below = s.uv[:, 1] > K.cy + 5
    assert np.allclose(s.z[road & below], HEIGHT * K.fy / (s.uv[road & below, 1] - K.cy), rtol=1e-6)
    # two faces, two objects, at 8 m and 20 m from the camera
    ids = np.unique(s.obj[s.obj >= 0])
    assert len(ids) == 2
    van = s.obj == s.obj[np.argmax(s.z * (s.kind == "object"))]
    assert np.median(s.z[van]) > 21.0
    # an object's distance is its nearest part, not the depth of its average point
    pred_d, true_d = object_distances(s.z * 1.3, s)
    assert sorted(true_d) == pytest.approx([8.0, 20.0], abs=0.1)
    assert pred_d / true_d == pytest.approx([1.3, 1.3])
    # heights above the road: the faces span 0.5-1.5 m, the van's roof is at 1.5 m
    obj = s.kind == "object"
    assert s.above[obj].min() == pytest.approx(0.5, abs=1e-6) and s.above[obj].max() == pytest.approx(1.5, abs=1e-6)
    low, high = s.points("object 0.3-1 m"), s.points("object 1-2.5 m")
    assert not (low & high).any() and np.array_equal(low | high, obj)
    assert np.allclose(s.above[low], np.round(s.above[low] / 0.05) * 0.05) and s.above[low].max() < 1.0
    # the camera is 1.6 m up: a point below its height shows below the image centre row
    assert (s.uv[low, 1] > K.cy).all() and np.array_equal(s.points("road"), s.kind == "road")


def test_other_cameras_look_their_own_way():
    """A camera yawed 60 degrees left reads as a dashcam looking its own way (yaw 0), same height;
    taken against the car's axis its yaw is beyond what a mounting allows."""
    t_vc = np.array([1.5, 0.5, HEIGHT])
    img = np.zeros((480, 640, 3), np.uint8)
    side = _ddad_sample("side", img, K, _camera(60.0), t_vc, _scene(), front=False)
    assert side.camera.mounting.height_m == pytest.approx(HEIGHT, abs=1e-6)
    assert side.camera.mounting.yaw_deg == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(ValueError, match="yaw_deg"):
        _ddad_sample("front", img, K, _camera(60.0), t_vc, _scene())


def test_frame_errors_sum_each_frames_points_in_the_span_and_pool_them():
    from bsn_edge.benchmarks.bench_realcam import FrameErrors
    preds = [np.array([6.0, 12.0, 50.0, 0.0]), np.array([9.0])]
    truths = [np.array([5.0, 10.0, 45.0, 8.0]), np.array([10.0])]
    e = FrameErrors.of(preds, truths)
    # frame 0: 0.2 + 0.2 (45 m is out of 5-40 m, a point without a prediction is left out); frame 1: 0.1
    np.testing.assert_allclose(e.sums, [0.4, 0.1])
    np.testing.assert_array_equal(e.counts, [2, 1])
    assert e.abs_rel() == pytest.approx(0.5 / 3)
    np.testing.assert_allclose(e.abs_rel(np.array([[1, 1], [0, 1]])), [0.1, 0.5 / 3])


def test_the_interval_is_the_frames_spread_and_a_models_difference_is_paired():
    from bsn_edge.benchmarks.bench_realcam import FrameErrors, interval_table
    same = FrameErrors(np.full(6, 2.0), np.full(6, 10))                 # every frame 0.2
    spread = FrameErrors(np.array([1.0, 1.0, 1.0, 1.0, 1.0, 7.0]), np.full(6, 10))   # pooled 0.2 too
    worse = FrameErrors(spread.sums * 1.1, spread.counts)               # 10 % worse in every frame
    lines, out = interval_table({"flat / road": {"A": same, "B": spread},
                                 "spread / road": {"A": spread, "B": spread}}, ["A", "B"])
    assert len(lines) == 2 + 2
    # identical frames leave nothing to resample
    assert out["flat / road"]["A"]["interval"] == pytest.approx([0.2, 0.2])
    # one frame far off: the interval holds the pooled value and reaches towards both extremes
    lo, hi = out["flat / road"]["B"]["interval"]
    assert out["flat / road"]["B"]["abs_rel"] == pytest.approx(0.2)
    assert 0.1 <= lo < 0.2 < hi <= 0.7
    # a model against itself differs by exactly 0 in every resample: not apart
    assert out["spread / road"]["B"]["minus_first"] == {"diff": 0.0, "interval": [0.0, 0.0], "apart": False}
    # 10 % worse in every frame: the paired difference is apart from 0 though the two intervals overlap
    _, out = interval_table({"spread / road": {"A": spread, "C": worse}}, ["A", "C"])
    d = out["spread / road"]["C"]["minus_first"]
    assert d["apart"] and d["interval"][0] > 0 and d["diff"] == pytest.approx(0.02)
    assert out["spread / road"]["C"]["interval"][0] < out["spread / road"]["A"]["interval"][1]


def test_two_models_of_one_file_name_are_refused_before_anything_runs(tmp_path, capsys):
    from bsn_edge.benchmarks.bench_realcam import main
    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "out"), "--model", "a/model.onnx", "--model", "b/model.onnx"])
    assert e.value.code == 2 and "two models are named 'model'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_models_are_named_by_name_or_by_file_stem_in_their_order():
    from bsn_edge.benchmarks.common import named

    assert named(["default=a/model.onnx", "b/leg.onnx", "control=c/model.onnx"]) == {
        "default": "a/model.onnx", "leg": "b/leg.onnx", "control": "c/model.onnx"}
    assert list(named(["z=1.onnx", "a=2.onnx"])) == ["z", "a"]
    with pytest.raises(ValueError, match="two models are named 'leg'"):
        named(["a/leg.onnx", "leg=b/x.onnx"])


def test_a_model_is_read_at_the_threshold_after_its_at_sign_and_named_by_it():
    from bsn_edge.benchmarks.common import load_engine, named, operating_point
    from bsn_edge.default_model import DEFAULT_MODEL

    assert operating_point("a/leg.onnx@0.2") == ("a/leg.onnx", 0.2)
    assert operating_point("a/leg.onnx") == ("a/leg.onnx", None)
    assert operating_point("a/we@ird.onnx") == ("a/we@ird.onnx", None)
    assert named(["a/leg.onnx@0.2", "a/leg.onnx", "low=a/leg.onnx@0.1"]) == {
        "leg@0.2": "a/leg.onnx@0.2", "leg": "a/leg.onnx", "low": "a/leg.onnx@0.1"}
    engine = load_engine(f"{DEFAULT_MODEL}@0.2")
    assert engine.threshold == 0.2 and engine.card.threshold not in (None, 0.2)
    assert load_engine(str(DEFAULT_MODEL)).threshold == engine.card.threshold
    with pytest.raises(ValueError, match=r"probability in \(0, 1\), got 1.5"):
        load_engine(f"{DEFAULT_MODEL}@1.5")
