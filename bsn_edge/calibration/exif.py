"""A picture's lens from its EXIF record: the first guess of a camera nobody calibrated, for photos.

A photo from a phone or a camera usually says its lens in its EXIF record, as the focal length a
35 mm film camera would need for the same view (``FocalLengthIn35mmFilm``, tag 0xA405). That fixes
the field of view, which no road in a still can (every ratio on the road plane is free of the focal
length): the 35 mm frame's diagonal (43.3 mm) spans the picture's diagonal, so
``f_px = f_35mm * hypot(width, height) / hypot(36, 24)``. Square pixels, principal point at the
centre, no lens distortion, no mounting (online calibration finds it), as
:func:`~bsn_edge.calibration.field_of_view.from_field_of_view` makes a camera from a data sheet.
Video files and pictures without the tag give nothing: the model camera is assumed as before.

Only the standard library reads the record (JPEG's APP1 segment: a TIFF header, IFD0, the Exif
IFD), so ``bsn-run`` needs nothing more than it has.
"""

from __future__ import annotations

import math
import os
import struct
from dataclasses import replace
from pathlib import Path

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.calibration.field_of_view import HFOV_RANGE_DEG
from bsn_edge.camera import Intrinsics
from bsn_edge.user_file import read_user_file

FILM_DIAGONAL_MM = math.hypot(36.0, 24.0)
EXIF_IFD_POINTER = 0x8769
FOCAL_35MM = 0xA405
MAKE, MODEL = 0x010F, 0x0110
_ASCII, _SHORT, _LONG = 2, 3, 4
_HEAD_BYTES = 1 << 16      # the APP1 segment is at most 64 KiB and comes first


def focal_35mm(path: str | os.PathLike) -> float | None:
    """The 35 mm equivalent focal length in millimetres a JPEG's EXIF record gives, or None (not a
    JPEG, no EXIF, no such tag, or a record that does not parse)."""
    found = _record(path)
    if found is None:
        return None
    tiff, order, ifd0 = found
    try:
        exif = _tag(tiff, order, ifd0, EXIF_IFD_POINTER)
        value = None if exif is None else _tag(tiff, order, exif, FOCAL_35MM)
    except (struct.error, IndexError):
        return None
    return float(value) if value else None


def camera_of(path: str | os.PathLike) -> tuple[str, str, float | None] | None:
    """Which camera took the picture, as its EXIF record says: maker, model and 35 mm equivalent
    focal length (a zoom's setting tells two lenses apart); None without a record."""
    found = _record(path)
    if found is None:
        return None
    tiff, order, ifd0 = found
    try:
        make, model = _text(tiff, order, ifd0, MAKE), _text(tiff, order, ifd0, MODEL)
    except (struct.error, IndexError):
        return None
    return make, model, focal_35mm(path)


def _record(path: str | os.PathLike) -> tuple[bytes, str, int] | None:
    """A JPEG's EXIF TIFF block, its byte order and the offset of its first IFD; None without one."""
    try:
        head = read_user_file(path, "picture", head=_HEAD_BYTES + 4)
    except (OSError, ValueError):          # a FIFO or a device named like a picture has no EXIF
        return None
    tiff = _exif_tiff(head)
    if tiff is None or len(tiff) < 8 or tiff[:2] not in (b"II", b"MM"):
        return None
    order = "<" if tiff[:2] == b"II" else ">"
    if struct.unpack(order + "H", tiff[2:4])[0] != 42:
        return None
    return tiff, order, struct.unpack(order + "I", tiff[4:8])[0]


def from_exif(path: str | os.PathLike, width: int, height: int) -> Calibration | None:
    """The camera of a picture ``width`` x ``height`` (as decoded, EXIF rotation applied) from its
    file's 35 mm equivalent focal length: intrinsics only; None when the file does not say it, or
    says a field of view no forward camera has."""
    f35 = focal_35mm(path)
    if f35 is None:
        return None
    fx = f35 * math.hypot(width, height) / FILM_DIAGONAL_MM
    hfov = math.degrees(2.0 * math.atan(width / (2.0 * fx)))
    if not HFOV_RANGE_DEG[0] <= hfov <= HFOV_RANGE_DEG[1]:
        return None
    cal = Calibration.of(Intrinsics.from_fov(width, height, hfov))
    return replace(cal, intrinsics_method=f"EXIF of {Path(path).name}: {f35:g} mm (35 mm equivalent), "
                                          f"{hfov:.1f} degrees across")


def _exif_tiff(head: bytes) -> bytes | None:
    """The TIFF block of the APP1 ``Exif`` segment among a JPEG's first segments."""
    if head[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(head) and head[i] == 0xFF:
        marker, size = head[i + 1], struct.unpack(">H", head[i + 2:i + 4])[0]
        if marker == 0xE1 and head[i + 4:i + 10] == b"Exif\x00\x00":
            return head[i + 10:i + 2 + size]
        if marker == 0xDA or size < 2:             # the picture's data begins: no EXIF before it
            return None
        i += 2 + size
    return None


def _text(tiff: bytes, order: str, ifd: int, tag: int) -> str:
    """The ASCII ``tag`` in the IFD at offset ``ifd`` ("" when absent)."""
    (count,) = struct.unpack(order + "H", tiff[ifd:ifd + 2])
    for k in range(count):
        entry = ifd + 2 + 12 * k
        t, kind, n = struct.unpack(order + "HHI", tiff[entry:entry + 8])
        if t != tag or kind != _ASCII:
            continue
        at = entry + 8 if n <= 4 else struct.unpack(order + "I", tiff[entry + 8:entry + 12])[0]
        return tiff[at:at + n].split(b"\x00", 1)[0].decode("ascii", "replace").strip()
    return ""


def _tag(tiff: bytes, order: str, ifd: int, tag: int) -> int | None:
    """The value of a SHORT or LONG ``tag`` with one value in the IFD at offset ``ifd``, or None."""
    (count,) = struct.unpack(order + "H", tiff[ifd:ifd + 2])
    for k in range(count):
        entry = ifd + 2 + 12 * k
        t, kind, n = struct.unpack(order + "HHI", tiff[entry:entry + 8])
        if t != tag:
            continue
        if n != 1 or kind not in (_SHORT, _LONG):
            return None
        fmt = order + ("H" if kind == _SHORT else "I")     # one value sits at the start of the entry's last 4 bytes
        return struct.unpack(fmt, tiff[entry + 8:entry + 8 + struct.calcsize(fmt)])[0]
    return None
