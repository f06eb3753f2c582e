"""The size a picture declares, read from its header: against OpenCV's encoder and PIL's reader (independent
of the code under test), and on any bytes at all without raising."""

from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bsn_edge.sequence.picture_header import PIXEL_BUDGET, declared_size, within_budget

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real"


def _encoded(ext: str, w: int, h: int) -> bytes:
    ok, buf = cv2.imencode(ext, np.full((h, w, 3), 90, np.uint8))
    assert ok
    return buf.tobytes()


@pytest.mark.parametrize("ext", [".jpg", ".png", ".bmp"])
@pytest.mark.parametrize("w,h", [(1, 1), (64, 48), (640, 360), (333, 1001)])
def test_the_size_opencv_wrote_is_the_size_read(ext, w, h):
    assert declared_size(_encoded(ext, w, h)) == (w, h)


def test_real_pictures_declare_the_size_pil_reads():
    pictures = [p for p in REAL.rglob("*") if p.suffix.lower() in (".jpg", ".jpeg", ".png", ".bmp")] \
        if REAL.is_dir() else []
    if not pictures:
        pytest.skip(f"real data absent: {REAL}")
    from PIL import Image

    for p in pictures:
        with Image.open(p) as im:
            assert declared_size(p.read_bytes()) == im.size, p


def sof_patched(data: bytes, w: int, h: int) -> bytes:
    """A JPEG whose start-of-frame header is made to declare ``w`` x ``h`` (the data stays the small one)."""
    i = data.index(b"\xff\xc0")
    out = bytearray(data)
    out[i + 5:i + 9] = h.to_bytes(2, "big") + w.to_bytes(2, "big")
    return bytes(out)


def test_a_header_that_lies_is_read_as_it_lies_and_held_to_the_budget():
    lying = sof_patched(_encoded(".jpg", 64, 64), 60000, 60000)
    assert declared_size(lying) == (60000, 60000) and not within_budget(declared_size(lying))
    assert within_budget((6000, 4000)) and not within_budget((5001, 5000)) and PIXEL_BUDGET == 5000 * 5000
    assert not within_budget((0, 10)) and not within_budget(None)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_any_bytes_give_a_size_or_none_never_an_error(data):
    got = declared_size(data)
    assert got is None or (len(got) == 2 and all(isinstance(v, int) and v >= 0 for v in got))


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([".jpg", ".png", ".bmp"]), st.lists(st.tuples(st.integers(0, 63), st.integers(0, 255)),
                                                          min_size=1, max_size=6), st.integers(0, 64))
def test_mutated_headers_give_a_size_or_none_never_an_error(ext, edits, cut):
    """A real picture's first bytes changed and its end cut off: a size or None, never an exception."""
    data = bytearray(_encoded(ext, 40, 30))
    for at, value in edits:
        data[at] = value
    got = declared_size(bytes(data[:len(data) - cut]))
    assert got is None or len(got) == 2
