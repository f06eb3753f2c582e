"""``bsn-synth``, ``bsn-sheet`` and the files they write."""

import json

import cv2
import numpy as np
import pytest

from bsn_edge.cli import sheet, synth
from bsn_edge.sequence import SequenceMeta, read_depth, read_kitti_poses, read_mask

ARGS = ["--frames", "4", "--size", "48x96", "--seed", "7"]


def test_writes_a_complete_sequence_folder(tmp_path):
    out = tmp_path / "seq"
    assert synth.main([str(out), *ARGS]) == 0
    meta = SequenceMeta.read(out)
    assert (meta.width, meta.height, meta.frames, meta.source, meta.seed) == (96, 48, 4, "synth", 7)
    assert read_kitti_poses(out / "poses.txt").shape == (4, 4, 4)
    for sub in ("rgb", "depth", "semantic", "bsgt", "boxes"):
        assert len(list((out / sub).iterdir())) == 4, sub
    assert read_depth(out / "depth" / "000000.png").shape == (48, 96)
    assert read_mask(out / "bsgt" / "000003.png").dtype == bool
    boxes = np.load(out / "boxes" / "000000.npy")
    assert boxes.ndim == 2 and boxes.shape[1] == 8
    cap = cv2.VideoCapture(str(out / "video.mp4"))
    assert cap.isOpened() and int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 4
    cfg = json.loads((out / "synth_config.json").read_text())
    assert cfg["config"]["seed"] == 7
    assert not list(out.rglob("*.tmp")), "no temporary files left behind"


def test_same_seed_same_bytes(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert synth.main([str(a), *ARGS, "--no-video"]) == 0
    assert synth.main([str(b), *ARGS, "--no-video"]) == 0
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert len(files) > 20
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel


def test_refuses_to_overwrite_without_force(tmp_path, capsys):
    out = tmp_path / "seq"
    assert synth.main([str(out), *ARGS, "--no-video"]) == 0
    before = (out / "rgb" / "000000.png").read_bytes()
    assert synth.main([str(out), *ARGS, "--no-video"]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "rgb" / "000000.png").read_bytes() == before, "nothing already written is lost"
    assert synth.main([str(out), "--frames", "2", "--size", "48x96", "--no-video", "--force"]) == 0
    assert len(list((out / "rgb").iterdir())) == 2


def test_force_keeps_files_it_does_not_own(tmp_path):
    out = tmp_path / "seq"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert synth.main([str(out), *ARGS, "--no-video", "--force"]) == 0
    assert (out / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("argv, message", [
    (["--size", "256by512"], "HEIGHTxWIDTH"),
    (["--style", "desert"], "invalid choice"),
])
def test_bad_arguments_are_explained(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        synth.main([str(tmp_path / "x"), *argv])
    assert e.value.code == 2
    assert message in capsys.readouterr().err


def test_bad_values_are_explained(tmp_path, capsys):
    assert synth.main([str(tmp_path / "x"), "--frames", "0"]) == 2
    assert "frames must be >= 1" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_contact_sheet(tmp_path, capsys):
    seq = tmp_path / "seq"
    assert synth.main([str(seq), *ARGS, "--no-video"]) == 0
    png = tmp_path / "sheet.png"
    assert sheet.main([str(seq), str(seq), "--out", str(png), "--rows", "2"]) == 0
    img = cv2.imread(str(png))
    assert img.shape[1] == 4 * 96 and img.shape[0] > 2 * 2 * 48
    assert sheet.main([str(tmp_path / "missing"), "--out", str(tmp_path / "other.png")]) == 2
    assert "not a sequence folder" in capsys.readouterr().err
