"""``can:IFACE:CHANNEL``: the alerts on a CAN bus through python-can (loaded when the sender opens), with its log."""

from __future__ import annotations

import contextlib
import time

from bsn_edge.alerts.bus_config import BusConfig
from bsn_edge.alerts.health import Fault
from bsn_edge.alerts.senders import Encoder, Sender, transmit_buffer_full

BLF_BLOCK_BYTES = 1024


class CanSender(Sender):
    """python-can on any interface (``socketcan``, ``virtual``, vendor ones), loaded lazily.
    Optionally logs every sent frame (``.log`` candump, ``.asc``, ``.blf``) through python-can's
    writers, flushed every cycle so that a crash loses at most the cycle in flight. The log is an
    output beside the bus: when it fails (a full disk) it is given up and counted in
    ``stats.log_errors``; the frames still go out."""

    name = "can"
    scheme = "can"

    def __init__(self, interface: str, channel: str, log_path: str | None = None, bus=None,
                 timeout_s: float = 0.01, encoder: Encoder | None = None) -> None:
        super().__init__(encoder)
        import can

        self._can = can
        self.bus = bus if bus is not None else can.Bus(interface=interface, channel=channel)
        self.timeout_s = timeout_s
        self.logger = can.Logger(log_path) if log_path else None
        if self.logger is not None and hasattr(self.logger, "max_container_size"):
            # BLF writes compressed blocks, 128 KiB by default: over a minute of this bus's frames, all of it
            # lost at a kill; a block of BLF_BLOCK_BYTES is about half a second of them
            self.logger.max_container_size = BLF_BLOCK_BYTES

    def _send(self, frames: list[tuple[int, bytes]]) -> None:
        for fid, data in frames:
            msg = self._can.Message(arbitration_id=fid, data=data, is_extended_id=False, timestamp=time.time(),
                                    is_rx=False)
            try:
                self.bus.send(msg, timeout=self.timeout_s)
            except self._can.CanOperationError as e:
                if transmit_buffer_full(e):
                    self.stats.full += 1
                    self._met_fault(Fault.TX_FULL)
                raise
            self._log(msg)
        self._flush_log()

    def _log(self, msg) -> None:
        if self.logger is None:
            return
        try:
            self.logger.on_message_received(msg)
        except Exception as e:
            self._log_failed(e)

    def _flush_log(self) -> None:
        if self.logger is None:
            return
        try:
            f = getattr(self.logger, "file", None)
            if f is not None and not getattr(f, "closed", False):
                f.flush()
        except Exception as e:
            self._log_failed(e)

    def _log_failed(self, e: Exception) -> None:
        self.stats.log_errors += 1
        self.stats.log_error = f"{type(e).__name__}: {e}"
        self._met_fault(Fault.SINK_ERRORS)
        logger, self.logger = self.logger, None
        if logger is not None:
            with contextlib.suppress(Exception):
                logger.stop()

    def _close(self) -> None:
        if self.logger is not None:
            try:
                self.logger.stop()
            except Exception as e:
                self.stats.log_errors += 1
                self.stats.log_error = f"{type(e).__name__}: {e}"
            self.logger = None
        self.bus.shutdown()

    @classmethod
    def from_target(cls, target: str, encoder: Encoder | None, log_path: str | None, bus: BusConfig) -> Sender:
        iface, _, channel = target.partition(":")
        if not (iface and channel):
            raise ValueError(f"can:{target}: give can:IFACE:CHANNEL, e.g. can:socketcan:can0")
        return cls(iface, channel, log_path=log_path, encoder=encoder, timeout_s=bus.can_timeout_s)
