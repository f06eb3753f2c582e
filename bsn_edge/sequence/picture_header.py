"""The size a picture file declares, read from its header before anything is decoded.

A decoder allocates what the header says: a 64x64 JPEG whose frame header claims 60000x60000 makes
OpenCV raise, and a real 20000x20000 one takes gigabytes. The runtime reads the declared size first
(JPEG's start-of-frame, PNG's IHDR, BMP's info header) and holds it to a pixel budget, so a picture
over the budget, or one whose header cannot be read, is a counted decode fault, never an allocation.
"""

from __future__ import annotations

import struct

# the most pixels a picture may declare: 25 megapixels (a 6000x4000 photo is 24)
PIXEL_BUDGET = 25_000_000

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# JPEG start-of-frame markers (baseline, extended, progressive, lossless; Huffman or arithmetic coded):
# every 0xC0-0xCF but DHT (C4), JPG (C8) and DAC (CC)
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_STANDALONE = frozenset(range(0xD0, 0xD8)) | {0x01}      # RSTn and TEM: no length follows
_SOS, _EOI = 0xDA, 0xD9


def declared_size(data: bytes) -> tuple[int, int] | None:
    """``(width, height)`` as the picture's header declares it; None for a header that cannot be read
    (cut, malformed, or not a JPEG, PNG or BMP)."""
    if data[:2] == b"\xff\xd8":
        return _jpeg(data)
    if data[:8] == _PNG_SIGNATURE:
        return _png(data)
    if data[:2] == b"BM":
        return _bmp(data)
    return None


def within_budget(size: tuple[int, int] | None, budget: int = PIXEL_BUDGET) -> bool:
    """Whether a declared size is a real picture's that the budget allows (both sides at least 1)."""
    return size is not None and size[0] >= 1 and size[1] >= 1 and size[0] * size[1] <= budget


def _jpeg(data: bytes) -> tuple[int, int] | None:
    i, n = 2, len(data)
    while i < n:
        if data[i] != 0xFF:
            return None                             # a marker must start here
        while i < n and data[i] == 0xFF:            # fill bytes
            i += 1
        if i >= n:
            return None
        marker = data[i]
        i += 1
        if marker in _STANDALONE:
            continue
        if marker in (_SOS, _EOI) or i + 2 > n:
            return None                             # the picture's data begins (or ends) before a frame header
        length = struct.unpack_from(">H", data, i)[0]
        if length < 2:
            return None
        if marker in _SOF:
            if length < 7 or i + 7 > n:
                return None
            height, width = struct.unpack_from(">HH", data, i + 3)
            return width, height
        i += length
    return None


def _png(data: bytes) -> tuple[int, int] | None:
    if len(data) < 24 or data[12:16] != b"IHDR":
        return None
    width, height = struct.unpack_from(">II", data, 16)
    return width, height


def _bmp(data: bytes) -> tuple[int, int] | None:
    if len(data) < 18:
        return None
    header = struct.unpack_from("<I", data, 14)[0]
    if header == 12 and len(data) >= 22:              # OS/2 BITMAPCOREHEADER: 16-bit sides
        width, height = struct.unpack_from("<HH", data, 18)
        return width, height
    if header >= 40 and len(data) >= 26:
        width, height = struct.unpack_from("<ii", data, 18)
        return (width, abs(height)) if width > 0 else None     # a negative height: rows top-down
    return None
