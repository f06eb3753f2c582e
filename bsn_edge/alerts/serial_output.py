"""``serial:URL``: the alerts on a serial line through pyserial (loaded when the sender opens), COBS-framed."""

from __future__ import annotations

import contextlib
import time

from bsn_edge.alerts.bus_config import BusConfig
from bsn_edge.alerts.health import Fault
from bsn_edge.alerts.senders import Encoder, Sender
from bsn_edge.alerts.serial_codec import encode_frame


class SerialSender(Sender):
    """pyserial on any URL pyserial understands (``/dev/ttyUSB0``, ``loop://``, ``socket://``...).
    A port that disappears is reopened with back-off (at most every ``retry_s``)."""

    name = "serial"
    scheme = "serial"
    tx_fault = Fault.SERIAL_ERRORS

    def __init__(self, url: str, baudrate: int = 115200, port=None, retry_s: float = 1.0,
                 encoder: Encoder | None = None, write_timeout_s: float = 0.05) -> None:
        super().__init__(encoder)
        import serial

        self._serial = serial
        self.url, self.baudrate, self.retry_s, self.write_timeout_s = url, baudrate, retry_s, write_timeout_s
        self.port = port if port is not None else self._open()
        self._next_retry = 0.0

    def _reopen(self) -> None:
        now = time.monotonic()
        if now < self._next_retry:
            raise OSError(f"serial port {self.url} is down; next retry in {self._next_retry - now:.1f} s")
        self._next_retry = now + self.retry_s
        self.port = self._open()
        self.stats.reconnects += 1

    def _open(self):
        return self._serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0,
                                           write_timeout=self.write_timeout_s)

    def _send(self, frames: list[tuple[int, bytes]]) -> None:
        if self.port is None or not self.port.is_open:
            self._reopen()
        payload = b"".join(encode_frame(fid, data) for fid, data in frames)
        try:
            self.port.write(payload)
        except (self._serial.SerialException, OSError):
            with contextlib.suppress(Exception):  # the port may already be gone
                self.port.close()
            self.port = None
            raise

    def _close(self) -> None:
        if self.port is not None:
            self.port.close()

    @classmethod
    def from_target(cls, target: str, encoder: Encoder | None, log_path: str | None, bus: BusConfig) -> Sender:
        if log_path:
            raise ValueError("a serial output keeps no CAN log")
        return cls(target, bus.serial_baud, retry_s=bus.serial_retry_s, encoder=encoder,
                   write_timeout_s=bus.serial_write_timeout_s)
