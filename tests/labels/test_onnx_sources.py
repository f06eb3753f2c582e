"""``--depth onnx:MODEL`` and ``--seg onnx:MODEL`` with small models the tests build."""

import shutil

import cv2
import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.labels import ClipRejectedError, LabelConfig, Sources, label_sequence, labels_dir
from bsn_edge.labels.generator import StaleLabelsError
from bsn_edge.labels.sources.base import ClipData
from bsn_edge.labels.sources.files import frame_count
from bsn_edge.labels.sources.onnx_depth import AlignedDepth
from bsn_edge.labels.sources.onnx_seg import OnnxSeg
from bsn_edge.sequence import SequenceMeta, read_depth, read_kitti_poses, read_mask
from bsn_edge.synth import SynthConfig, write_clip
from tests.labels.onnx_models import channel_model

CFG = LabelConfig(rate=5.0, horizon_s=1.0)
SHIPPED = DEFAULT_MODEL
IDENTITY_NORM = {"bsn.mean": [0, 0, 0], "bsn.std": [1, 1, 1]}


@pytest.fixture(scope="module")
def encoded(tmp_path_factory):
    """A clip whose blue channel carries 2 / depth (an 'inverse depth' a model can read back)."""
    root = tmp_path_factory.mktemp("onnx")
    seq = root / "seq"
    write_clip(SynthConfig(frames=30, height=96, width=192, fps=10.0, camera="fixed", seed=3), seq, video=False)
    for i in range(30):
        p = seq / "rgb" / f"{i:06d}.png"
        img = cv2.imread(str(p))
        d = read_depth(seq / "depth" / f"{i:06d}.png")
        img[..., 0] = np.where(d > 0, np.clip(255 * 2.0 / np.maximum(d, 1e-3), 0, 255), 0).astype(np.uint8)
        cv2.imwrite(str(p), img)
    return seq


def test_relative_depth_is_aligned_to_metres_by_landmarks(tmp_path):
    """An affine-distorted inverse depth (as a MiDaS-like network gives) comes back in metres."""
    seq = tmp_path / "plain"
    write_clip(SynthConfig(frames=30, height=256, width=512, fps=10.0, camera="fixed", seed=3), seq, video=False)
    meta = SequenceMeta.read(seq)
    clip = ClipData(seq, meta, frame_count(seq))
    poses = read_kitti_poses(seq / "poses.txt")

    def predict(i):
        d = read_depth(seq / "depth" / f"{i:06d}.png")
        return np.where(d > 0, 7.0 / np.maximum(d, 1e-3) + 0.03, 0.03).astype(np.float32)
    depth = AlignedDepth(predict, "inverse_depth", clip, poses, list(range(0, 30, 2)), min_corr=0.7)
    assert depth.describe()["correlation"] > 0.9
    errs = []
    for i in range(0, 30, 2):
        true = read_depth(seq / "depth" / f"{i:06d}.png")
        near = (true > 2) & (true < 30)
        errs.append(np.median(np.abs(depth(i)[near] - true[near]) / true[near]))
    # the landmarks' metric scale comes from the odometry (camera height over the road plane), a few
    # per cent off on this clip; the affine fit itself is exact
    assert np.median(errs) < 0.07, f"median relative depth error per frame {np.round(errs, 3)}"


def test_labels_from_a_depth_model(encoded, tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(encoded, seq)
    model = channel_model(tmp_path / "inv.onnx", [2], {**IDENTITY_NORM, "bsn.depth_kind": "inverse_depth"})
    rep = label_sequence(seq, CFG, Sources(depth=f"onnx:{model}"))
    detail = rep["sources_detail"]["depth"]
    assert rep["status"] == "ok" and detail["kind"] == "onnx" and detail["prediction"] == "inverse_depth"
    assert detail["correlation"] > 0.7 and detail["landmarks"] > 100
    exact = tmp_path / "exact"
    shutil.copytree(encoded, exact)
    label_sequence(exact, CFG)
    inter = union = 0
    for p in sorted((labels_dir(exact, CFG) / "blindspot").iterdir()):
        got, true = read_mask(labels_dir(seq, CFG) / "blindspot" / p.name), read_mask(p)
        inter, union = inter + int((got & true).sum()), union + int((got | true).sum())
    # a 30 % depth-scale error brings it to 0.55; the landmarks' fit is about 15 % long at this size
    assert union > 0 and inter / union > 0.65, f"IoU {inter / union:.2f} against the labels from the depth files"


def test_depth_model_unrelated_to_depth_is_rejected(encoded, tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(encoded, seq)
    model = channel_model(tmp_path / "noise.onnx", [1], {**IDENTITY_NORM, "bsn.depth_kind": "depth"},
                          noise=True)
    cfg = LabelConfig(rate=5.0, horizon_s=1.0, min_corr=0.7)
    with pytest.raises(ClipRejectedError, match=r"correlation|cannot be aligned"):
        label_sequence(seq, cfg, Sources(depth=f"onnx:{model}"))
    import json
    rep = json.loads((seq / "labels" / "T1s" / "report.json").read_text())
    assert rep["status"] == "rejected" and rep["reason"]


def test_seg_model_with_a_class_map(encoded, tmp_path):
    # two scores, R and B (RGB order): the larger wins; class 0 -> road, class 1 -> sky
    model = channel_model(tmp_path / "seg.onnx", [0, 2], {**IDENTITY_NORM, "bsn.class_map": [0, 10]})
    meta = SequenceMeta.read(encoded)
    seg = OnnxSeg(str(model), ClipData(encoded, meta, frame_count(encoded)))
    img = cv2.imread(str(encoded / "rgb" / "000004.png"))
    expected = np.where(img[..., 2] >= img[..., 0], sm.ROAD, sm.SKY)
    out = seg(4)
    assert out.dtype == np.uint8 and (out == expected).mean() > 0.99


def test_seg_model_without_a_map_must_have_19_classes(encoded, tmp_path):
    model = channel_model(tmp_path / "seg3.onnx", [0, 1, 2], IDENTITY_NORM)
    meta = SequenceMeta.read(encoded)
    seg = OnnxSeg(str(model), ClipData(encoded, meta, frame_count(encoded)))
    with pytest.raises(ValueError, match=r"3 classes and no bsn\.class_map"):
        seg(0)


def test_uint8_bgr_models_and_missing_model(encoded, tmp_path):
    from bsn_edge.labels.sources.onnx_model import OnnxImageModel
    m = OnnxImageModel(channel_model(tmp_path / "u8.onnx", [0], uint8=True))
    img = cv2.imread(str(encoded / "rgb" / "000000.png"))
    np.testing.assert_allclose(m(img)[0], img[..., 0].astype(np.float32))
    with pytest.raises(FileNotFoundError, match="not found"):
        OnnxImageModel(tmp_path / "nope.onnx")


def test_monocular_pipeline_without_poses_or_metric_depth(tmp_path):
    """Relative inverse depth + segmentation + video: seed VO, windowed alignment, metres from
    the camera height, PnP VO. Its labels must agree with those from exact sources."""
    seq = tmp_path / "mono"
    write_clip(SynthConfig(frames=40, height=256, width=512, fps=10.0, camera="fixed", seed=5), seq, video=False,
               workers=2)
    (seq / "rel").mkdir()
    for i in range(40):
        d = read_depth(seq / "depth" / f"{i:06d}.png")
        np.save(seq / "rel" / f"{i:06d}.npy", np.where(d > 0, 9.0 / np.maximum(d, 1e-3), 0) + 0.05)
    exact = tmp_path / "exact"
    shutil.copytree(seq, exact)
    label_sequence(exact, CFG)
    (seq / "poses.txt").unlink()  # nothing to cheat with
    (seq / "depth").rename(seq / "depth_hidden")
    rep = label_sequence(seq, CFG, Sources(depth="rel:rel:inverse", poses="vo"))
    poses = rep["sources_detail"]["poses"]
    assert rep["status"] == "ok" and poses["kind"] == "vo" and poses["final"]["metric"]
    found = total = 0
    for p in sorted((exact / "labels" / "T1s" / "blindspot").iterdir()):
        ref = read_mask(p)
        found += (read_mask(seq / "labels" / "T1s" / "blindspot" / p.name) & ref).sum()
        total += ref.sum()
    assert total > 0 and found >= 0.5 * total, f"{found} of {total} exact-source label pixels"


def test_labels_with_the_depth_of_a_bsn_model_on_a_camera_it_never_saw(tmp_path):
    """``--depth bsn:MODEL`` with the shipped model on a 55-degree lens 1.2 m up (the model camera is
    80 degrees at 1.5 m): warped into the model camera and back, the model's metres need under 15 %
    of correction from the landmarks (a plain resize instead needs 29 %), and the road's depth
    agrees with the clip's own within 15 %."""
    seq = tmp_path / "seq"
    write_clip(SynthConfig(frames=30, height=360, width=640, fps=10.0, seed=11, camera="fixed", hfov_deg=55.0,
                           camera_height=1.2), seq, video=False, workers=2)
    truth = {i: read_depth(seq / "depth" / f"{i:06d}.png") for i in range(0, 30, 2)}
    road = {i: cv2.imread(str(seq / "semantic" / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED) == sm.ROAD for i in truth}
    rep = label_sequence(seq, CFG, Sources(depth=f"bsn:{SHIPPED}"))
    detail = rep["sources_detail"]["depth"]
    assert rep["status"] == "ok" and detail["kind"] == "bsn" and detail["variant"]
    assert abs(detail["clip_scale"] - 1) < 0.15, detail
    from bsn_edge.labels.sources.bsn_depth import BsnDepth
    meta = SequenceMeta.read(seq)
    depth = BsnDepth.for_clip(str(SHIPPED), ClipData(seq, meta, frame_count(seq)), read_kitti_poses(seq / "poses.txt"),
                              CFG, sorted(truth))
    errs = []
    for i, t in truth.items():
        got = depth(i)
        ok = road[i] & (t > 4) & (t < 30) & (got > 0)
        errs.append(np.median(np.abs(got[ok] - t[ok]) / t[ok]))
    assert np.median(errs) < 0.15, np.round(errs, 3)


def test_labels_are_stale_when_a_source_or_the_file_behind_it_changes(encoded, tmp_path):
    """Labels from the depth files, then asked of a depth model: refused, nothing touched. Labels
    from a model, then the model at the same path replaced by another: refused too."""
    seq = tmp_path / "seq"
    shutil.copytree(encoded, seq)
    label_sequence(seq, CFG)
    out = labels_dir(seq, CFG) / "blindspot"
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    model = channel_model(tmp_path / "inv.onnx", [2], {**IDENTITY_NORM, "bsn.depth_kind": "inverse_depth"})
    with pytest.raises(StaleLabelsError, match=r"depth 'files' -> 'onnx:"):
        label_sequence(seq, CFG, Sources(depth=f"onnx:{model}"))
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    label_sequence(seq, CFG, Sources(depth=f"onnx:{model}"), force=True)
    assert label_sequence(seq, CFG, Sources(depth=f"onnx:{model}"))["resumed_frames"] == 10
    # another model at the same path: the same channel read as depth, not inverse depth
    channel_model(model, [2], {**IDENTITY_NORM, "bsn.depth_kind": "depth"})
    with pytest.raises(StaleLabelsError, match=r"depth file's sha256 [0-9a-f]{12}\.\.\. -> [0-9a-f]{12}\.\.\."):
        label_sequence(seq, CFG, Sources(depth=f"onnx:{model}"))
