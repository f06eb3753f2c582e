"""End-to-end protection in the style of AUTOSAR E2E profile 1: an alive counter and a CRC-8."""

from __future__ import annotations

COUNTER_MOD = 15          # counter runs 0..14 (15 is reserved as 'invalid' in profile 1)


def e2e_crc(data: bytes, data_id: int) -> int:
    """The frame CRC: CRC-8 SAE J1850 over the data ID's two bytes (low, high), then ``data``,
    so a frame of one message can never pass as another's."""
    return crc8_sae_j1850(bytes([data_id & 0xFF, (data_id >> 8) & 0xFF]) + bytes(data))


def crc8_sae_j1850(data: bytes) -> int:
    """CRC-8 SAE J1850: poly 0x1D, init 0xFF, final xor 0xFF (check value 0x4B)."""
    crc = 0xFF
    for b in bytes(data):
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def crc16_ccitt(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), for serial frames."""
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


class AliveCounter:
    """0, 1, ..., 14, 0, ..."""

    def __init__(self) -> None:
        self.value = -1

    def next(self) -> int:
        self.value = (self.value + 1) % COUNTER_MOD
        return self.value


def counter_gap(previous: int | None, current: int) -> int:
    """Frames lost between two received counters (0 when consecutive)."""
    if previous is None:
        return 0
    return (current - previous - 1) % COUNTER_MOD
