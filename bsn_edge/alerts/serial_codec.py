"""AlertFrames on a serial line: COBS-delimited frames carrying the CAN payloads plus a CRC-16.

Frame (before COBS): ``b'B'``, message id (2 bytes, little endian), the 8 CAN data bytes,
CRC-16/CCITT-FALSE of all that (2 bytes, little endian). Frames end with a zero byte, which
COBS guarantees appears nowhere else, so a receiver resynchronises after any corruption.
"""

from __future__ import annotations

from collections.abc import Iterator

from bsn_edge.alerts.e2e import crc16_ccitt

MAGIC = b"B"


def cobs_encode(data: bytes) -> bytes:
    out = bytearray()
    block = bytearray()
    for b in data:
        if b == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(b)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
    out.append(len(block) + 1)
    out += block
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    out = bytearray()
    i = 0
    while i < len(data):
        code = data[i]
        if code == 0 or i + code > len(data):
            raise ValueError("malformed COBS block")
        out += data[i + 1:i + code]
        i += code
        if code < 255 and i < len(data):
            out.append(0)
    return bytes(out)


def encode_frame(frame_id: int, payload: bytes) -> bytes:
    body = MAGIC + frame_id.to_bytes(2, "little") + payload
    return cobs_encode(body + crc16_ccitt(body).to_bytes(2, "little")) + b"\x00"


class FrameDecoder:
    """Feed bytes in any chunks; get back ``(frame_id, payload)`` of valid frames. Invalid frames
    (bad COBS, CRC or magic) are counted in ``errors`` and skipped."""

    def __init__(self) -> None:
        self.buf = bytearray()
        self.errors = 0

    def feed(self, data: bytes) -> Iterator[tuple[int, bytes]]:
        self.buf += data
        while True:
            try:
                end = self.buf.index(0)
            except ValueError:
                return
            raw = bytes(self.buf[:end])
            del self.buf[:end + 1]
            if not raw:
                continue
            try:
                body = cobs_decode(raw)
            except ValueError:
                self.errors += 1
                continue
            if len(body) < 5 or body[:1] != MAGIC or crc16_ccitt(body[:-2]) != int.from_bytes(body[-2:], "little"):
                self.errors += 1
                continue
            yield int.from_bytes(body[1:3], "little"), body[3:-2]
