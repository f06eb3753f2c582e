"""The training loader puts every clip in the model camera: a road seen by a drawn camera reads as
the model camera at its reference height would read it (analytic), and the hood is outside V."""

import cv2
import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.camera import Intrinsics
from bsn_edge.data import BlindSpotDataset
from bsn_edge.data.dataset import Clip
from bsn_edge.mounting import Mounting
from bsn_edge.sequence import write_mask
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.synth.rig import Rig

MODEL = Intrinsics.from_fov(256, 128, 80.0)
REF = Mounting(1.5, pitch_deg=1.5)


def road_z(K: Intrinsics, m: Mounting) -> np.ndarray:
    """z-depth where each pixel's ray meets a road ``m.height_m`` below (ray-plane, by hand)."""
    rays = K.rays().reshape(-1, 3).astype(np.float64)
    along = rays @ (m.rotation() @ np.array([0.0, 1.0, 0.0]))
    return np.where(along > 1e-6, m.height_m / np.maximum(along, 1e-6), 0.0).reshape(K.height, K.width)


def labelled_clip(tmp_path, seed):
    out = write_clip(SynthConfig(frames=1, height=192, width=384, seed=seed, parked=0, traffic=0, pedestrians=0),
                     tmp_path / f"c{seed}", video=False)
    lab = SequenceFolder(out).labels("T5s")
    lab.make_dirs()
    write_mask(lab.visibility(0), np.ones((192, 384), bool))
    write_mask(lab.blindspot(0), np.zeros((192, 384), bool))
    return Clip(out, "town", (0,))


def test_a_drawn_cameras_road_reads_as_the_model_camera_at_its_reference_height(tmp_path):
    seed = next(s for s in range(300) if (r := Rig.draw(s)).k1 < -0.03 and abs(r.yaw_deg) > 1 and r.hood == 0
                and abs(r.height_m - 1.5) > 0.2)
    ds = BlindSpotDataset([labelled_clip(tmp_path, seed)], (128, 256), camera=MODEL, mounting=REF)
    item = ds.load(0)
    want = road_z(MODEL, REF)
    road = (item["semantic"] == sm.ROAD) & (want > 4) & (want < 30)
    assert road.sum() > 500
    rel = np.abs(item["depth"][road] - want[road]) / want[road]
    assert np.median(rel) < 0.02, np.median(rel)
    # without the height ratio the depth would be off by the rig's height over the reference's
    assert abs(Rig.draw(seed).height_m / 1.5 - 1) > 0.12


def test_the_hood_and_what_the_clip_does_not_see_are_outside_v(tmp_path):
    seed = next(s for s in range(300) if Rig.draw(s).hood > 0.1)
    ds = BlindSpotDataset([labelled_clip(tmp_path, seed)], (128, 256), camera=MODEL, mounting=REF)
    item = ds.load(0)
    hood = item["semantic"] == sm.IGNORE
    assert hood[-3:, 100:156].all() and not item["visibility"][hood].any()
    assert cv2.countNonZero(item["visibility"]) > 0.3 * item["visibility"].size
