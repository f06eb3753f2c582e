"""CamVid's layout read in the project's vocabulary, on a tiny drive made here (the real frames are
used where they lie beside the checkout)."""

import cv2
import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.data import BlindSpotDataset, find_clips
from bsn_edge.labels import camvid


def _drive(root, name="0042AB", frames=(930, 960, 990), split="train"):
    d = root / split
    d.mkdir(parents=True, exist_ok=True)
    for k, f in enumerate(frames):
        img = np.full((72, 96, 3), 40 * k, np.uint8)
        lab = np.full((72, 96), 3, np.uint8)          # road
        lab[:20] = 0                                   # sky
        lab[40:60, 10:30] = 8                          # a car
        lab[40:60, 60:64] = 9                          # a pedestrian
        lab[0:2, 0:2] = 11                             # unlabelled
        cv2.imwrite(str(d / f"{name}_f{f:05d}.jpg"), img)
        cv2.imwrite(str(d / f"{name}_f{f:05d}_label.png"), lab)
    return root


def test_drives_are_ordered_by_video_frame_and_classes_map_to_train_ids(tmp_path):
    root = _drive(tmp_path, frames=(990, 930, 960))
    (d,) = camvid.drives(root)
    assert [f.video_frame for f in d.frames] == [930, 960, 990] and d.step_s == pytest.approx(1.0)
    sem = d.frames[0].semantic()
    assert sem[30, 50] == sm.ROAD and sem[5, 5] == sm.SKY and sem[50, 20] == sm.CAR
    assert sem[50, 61] == sm.PERSON and sem[0, 0] == sm.IGNORE
    (tmp_path / "train" / "0042AB_f00990_label.png").unlink()
    with pytest.raises(ValueError, match="no label beside it"):
        camvid.drives(root)


def test_a_drive_written_as_a_sequence_teaches_segmentation_and_no_blind_spot(tmp_path):
    (d,) = camvid.drives(_drive(tmp_path / "camvid"))
    out = camvid.write_sequence(d, tmp_path / "data" / "camvid_0042AB")
    with pytest.raises(FileExistsError):
        camvid.write_sequence(d, out)
    (clip,) = find_clips(tmp_path / "data")
    assert clip.style == "camvid" and clip.frames == (0, 1, 2)
    item = BlindSpotDataset([clip], (64, 128)).load(1)
    assert not item["visibility"].any() and not item["blindspot"].any()
    seen = item["semantic"][item["semantic"] != sm.IGNORE]
    assert {sm.ROAD, sm.SKY, sm.CAR} <= set(np.unique(seen).tolist())
