"""A folder of pictures is one camera only when its pictures say so; otherwise each is warped with its own
lens (its EXIF record's, checked against the 35 mm film geometry by hand) and the model camera's mounting,
runs whatever its size, and the summary and end lines say which was done."""

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from bsn_edge.calibration.exif import camera_of
from bsn_edge.calibration.folder_cameras import FolderCameras, judge_folder
from bsn_edge.cli import run as run_cli
from bsn_edge.runtime import Engine
from bsn_edge.runtime.picture_cameras import PictureCameras

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real"


def _photo(path: Path, rgb: np.ndarray, make: str | None, model: str = "", focal: int | None = None,
           big_endian: bool = False) -> None:
    exif = Image.Exif()
    if big_endian:
        exif.endian = ">"
    if make is not None:
        exif[0x010F], exif[0x0110] = make, model
    if focal is not None:
        exif.get_ifd(0x8769)[0xA405] = focal
    Image.fromarray(rgb).save(path, exif=exif)


def _frame(clip: Path, i: int, size: tuple[int, int] | None = None) -> np.ndarray:
    bgr = cv2.imread(str(clip / "rgb" / f"{i:06d}.png"))
    return cv2.cvtColor(bgr if size is None else cv2.resize(bgr, size), cv2.COLOR_BGR2RGB)


@pytest.mark.parametrize("big_endian", [False, True])
def test_the_exif_record_names_the_camera(tmp_path, big_endian):
    rgb = np.zeros((20, 30, 3), np.uint8)
    _photo(tmp_path / "a.jpg", rgb, "LG", "Phone model 7", 26, big_endian)      # "LG\0" sits inside its entry
    _photo(tmp_path / "b.jpg", rgb, "A maker", "", None, big_endian)
    cv2.imwrite(str(tmp_path / "c.jpg"), rgb)
    assert camera_of(tmp_path / "a.jpg") == ("LG", "Phone model 7", 26.0)
    assert camera_of(tmp_path / "b.jpg") == ("A maker", "", None)
    assert camera_of(tmp_path / "c.jpg") is None


def test_photos_from_different_cameras_are_each_their_own_camera_in_bsn_run(setup, tmp_path, capsys):
    model, clip = setup
    folder = tmp_path / "photos"
    folder.mkdir()
    _photo(folder / "a.jpg", _frame(clip, 0), "Maker", "One", 28)
    _photo(folder / "b.jpg", _frame(clip, 7, (240, 120)), "Maker", "Two", 24)
    _photo(folder / "c.jpg", _frame(clip, 14, (160, 120)), None)
    summary = tmp_path / "s.json"
    assert run_cli.main(["--model", str(model), "--source", str(folder), "--summary", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["frames"] == 3 and s["valid_frames"] == 3, "pictures of other sizes are run, each as its own camera"
    assert not s["faults"].get("size_changes")
    cam = s["camera"]
    assert cam["cameras"] == {"cameras": "each picture its own camera", "why": "their EXIF records name 3 cameras"}
    assert cam["lenses"] == {"exif": 2, "assumed": 1} and cam["calibrating"] and cam["first_guess"] is None
    said = capsys.readouterr()
    assert "each picture its own camera: their EXIF records name 3 cameras" in said.err
    assert "camera: each picture its own camera" in said.out and "lens from EXIF for 2, assumed for 1" in said.out


def test_each_picture_is_warped_with_its_own_lens(setup, tmp_path):
    model, clip = setup
    for name, focal, size in (("a.jpg", 28, (192, 96)), ("b.jpg", 50, (300, 200))):
        _photo(tmp_path / name, _frame(clip, 0, size), "Maker", name, focal)
    cams = PictureCameras(Engine(model).card, judge_folder([tmp_path / "a.jpg", tmp_path / "b.jpg"]))
    assert cams.verdict.cameras is FolderCameras.EACH
    for name, focal, (w, h) in (("a.jpg", 28, (192, 96)), ("b.jpg", 50, (300, 200)), ("a.jpg", 28, (192, 96))):
        frame = np.zeros((h, w, 3), np.uint8)
        cams.picture(tmp_path / name, frame)
        mf = cams.frame_for(frame)
        # 35 mm equivalent: the film's diagonal (43.27 mm) spans the picture's
        assert mf.raw.fx == pytest.approx(focal * math.hypot(w, h) / math.hypot(36, 24))
        assert (mf.raw.width, mf.raw.height) == (w, h)
        assert mf.mounting == cams._guess, "the model camera's mounting, assumed"
    cams.close()


def test_frames_of_one_clip_are_one_camera_and_a_damaged_frame_does_not_change_that(setup, tmp_path):
    _, clip = setup
    files = sorted((clip / "rgb").glob("*.png"))
    assert judge_folder(files).cameras is FolderCameras.ONE
    odd = tmp_path / "odd"
    odd.mkdir()
    for i, f in enumerate(files[:9]):
        img = cv2.imread(str(f))
        cv2.imwrite(str(odd / f.name), cv2.resize(img, (160, 120)) if i == 4 else img)
    assert judge_folder(sorted(odd.iterdir())).cameras is FolderCameras.ONE


def test_real_drives_a_second_apart_are_one_camera_and_pictures_of_three_drives_are_not():
    root = REAL / "camvid"
    if not root.is_dir():
        pytest.skip(f"real data absent: {root}")
    from bsn_edge.labels import camvid

    drives = [d for d in camvid.drives(root) if d.split == "train"]
    one = [f.image for f in drives[-1].frames[40:49]]
    mixed = [d.frames[k * 5].image for k in range(3) for d in drives]       # the three drives in turn
    assert judge_folder(one).cameras is FolderCameras.ONE
    verdict = judge_folder(mixed)
    assert verdict.cameras is FolderCameras.EACH and "consecutive pictures show one scene" in verdict.why


@pytest.fixture(scope="module")
def three_drives(tmp_path_factory):
    """Three rendered drives of other streets (town, suburb, urban; 10 frames/s), their frames half a
    second apart: the rendered twin of the real drives above, so the thresholds hold without real data.
    Measured: 12-105 matches on one geometry between a drive's consecutive pictures (61 or more in 21 of
    24 pairs), 14-18 between pictures of two drives."""
    from bsn_edge.synth import SynthConfig, write_clip

    root = tmp_path_factory.mktemp("drives")
    out = []
    for style, seed in (("town", 11), ("suburb", 12), ("urban", 13)):
        write_clip(SynthConfig(frames=41, height=240, width=480, seed=seed, style=style), root / style)
        out.append(sorted((root / style / "rgb").glob("*.png"))[::5])
    return out


def test_rendered_frames_half_a_second_apart_are_one_camera_and_three_drives_in_turn_are_not(three_drives):
    for drive in three_drives:
        assert judge_folder(drive).cameras is FolderCameras.ONE
    mixed = [three_drives[k % 3][k // 3] for k in range(9)]
    verdict = judge_folder(mixed)
    assert verdict.cameras is FolderCameras.EACH and "0 of 8 consecutive" in verdict.why


@pytest.mark.parametrize("order,cameras", [("A0 A1 B0 B1 C0 C1 A2 A3 B2", FolderCameras.ONE),
                                           ("A0 A1 B0 B1 C0 C1 A2 B2 C2", FolderCameras.EACH),
                                           ("A0 B0 C0 A1 B1 C1 A2 B2 C2", FolderCameras.EACH)])
def test_half_the_pairs_showing_one_scene_is_the_edge_of_one_camera(three_drives, order, cameras):
    """Drives A, B and C, their pictures half a second apart: 4 of 8 consecutive pairs showing one scene
    moving on is half, the least that is one camera; 3 of 8 is not, nor is none."""
    files = [three_drives["ABC".index(name[0])][int(name[1])] for name in order.split()]
    assert judge_folder(files).cameras is cameras


def test_a_picture_whose_header_lies_and_an_odd_one_first_each_cost_one_counted_frame(setup, tmp_path):
    """A 64x64 JPEG whose frame header claims 60000x60000 (OpenCV would raise, or allocate gigabytes),
    and an 80x80 picture sorted first in a folder of the clip's frames: each is one counted decode fault
    or size change; every other frame runs, and the folder's size is that of most of its pictures."""
    from tests.sequence.test_picture_header import sof_patched

    model, clip = setup
    folder = tmp_path / "pictures"
    folder.mkdir()
    files = sorted((clip / "rgb").glob("*.png"))[:8]
    for i, f in enumerate(files):
        cv2.imwrite(str(folder / f"{i + 1:03d}.jpg"), cv2.imread(str(f)))
    cv2.imwrite(str(folder / "000.jpg"), np.full((80, 80, 3), 120, np.uint8))
    _, buf = cv2.imencode(".jpg", np.full((64, 64, 3), 90, np.uint8))
    (folder / "004a.jpg").write_bytes(sof_patched(buf.tobytes(), 60000, 60000))
    summary = tmp_path / "s.json"
    assert run_cli.main(["--model", str(model), "--source", str(folder), "--calib", str(clip / "calibration.json"),
                         "--summary", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["frames"] == 10 and s["valid_frames"] == 8
    assert s["faults"]["decode_errors"] == 1 and s["faults"]["size_changes"] == 1
