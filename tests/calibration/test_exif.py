"""A picture's lens from its EXIF record: the 35 mm equivalent focal length against the field of view
it implies analytically (a 3:2 picture spans the 36 mm film width: hfov = 2 atan(18 / f)), records
written by Pillow (another EXIF writer, both byte orders), and every way a file can say nothing."""

import math

import cv2
import numpy as np
import pytest
from PIL import Image

from bsn_edge.calibration.exif import focal_35mm, from_exif


def _photo(path, focal: int | None, size=(300, 200), big_endian: bool = False, fmt: str = "JPEG") -> None:
    rng = np.random.default_rng(0)
    img = Image.fromarray(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8))
    exif = Image.Exif()
    if big_endian:
        exif.endian = ">"
    exif[0x010F] = "Phone maker"
    if focal is not None:
        exif.get_ifd(0x8769)[0xA405] = focal
    img.save(path, fmt, exif=exif)


@pytest.mark.parametrize("big_endian", [False, True])
@pytest.mark.parametrize("focal,hfov", [(18, 90.0), (36, 2 * math.degrees(math.atan(0.5)))])
def test_the_35mm_focal_length_gives_the_field_of_view_of_the_film_frame(tmp_path, big_endian, focal, hfov):
    path = tmp_path / "p.jpg"
    _photo(path, focal, big_endian=big_endian)
    assert focal_35mm(path) == focal
    cal = from_exif(path, 300, 200)
    k = cal.intrinsics
    assert math.degrees(2 * math.atan(150 / k.fx)) == pytest.approx(hfov, abs=1e-9)
    assert k.fx == k.fy and (k.cx, k.cy) == (150.0, 100.0) and cal.mounting is None and not cal.has_distortion
    assert cal.intrinsics_method == f"EXIF of p.jpg: {focal} mm (35 mm equivalent), {hfov:.1f} degrees across"


def test_another_aspect_keeps_the_diagonal_angle_of_view(tmp_path):
    # a 4:3 picture at 26 mm (a phone's main camera): "35 mm equivalent" keeps the angle across the
    # diagonal, which on film is 2 atan(21.63 / 26) = 79.5 degrees
    _photo(tmp_path / "p.jpg", 26, size=(400, 300))
    k = from_exif(tmp_path / "p.jpg", 4000, 3000).intrinsics
    assert 2 * math.degrees(math.atan(2500 / k.fx)) == pytest.approx(2 * math.degrees(math.atan(21.633 / 26)), abs=0.01)


def test_pictures_that_do_not_say_their_lens_give_nothing(tmp_path):
    _photo(tmp_path / "none.jpg", None)
    cv2.imwrite(str(tmp_path / "plain.jpg"), np.zeros((20, 30, 3), np.uint8))
    _photo(tmp_path / "p.png", 26, fmt="PNG")
    _photo(tmp_path / "whole.jpg", 26)
    (tmp_path / "cut.jpg").write_bytes((tmp_path / "whole.jpg").read_bytes()[:40])
    (tmp_path / "text.jpg").write_text("not a picture")
    for name in ("none.jpg", "plain.jpg", "p.png", "cut.jpg", "text.jpg", "missing.jpg"):
        assert focal_35mm(tmp_path / name) is None, name
        assert from_exif(tmp_path / name, 30, 20) is None, name
    _photo(tmp_path / "fisheye.jpg", 4)                  # 4 mm: wider than any forward camera
    assert focal_35mm(tmp_path / "fisheye.jpg") == 4 and from_exif(tmp_path / "fisheye.jpg", 300, 200) is None
