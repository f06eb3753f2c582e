"""Senders: where AlertFrames go. A sender that cannot send says so: every failure is counted in
``stats`` and reported by the send that met it (:class:`Sent`, which the send cycle adds to the status
message's fault counters), retried with back-off where that helps, and never raised into the caller's loop."""

from __future__ import annotations

import contextlib
import errno
import socket
import struct
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

from bsn_edge.alerts.bus_config import BusConfig
from bsn_edge.alerts.can_codec import CanEncoder
from bsn_edge.alerts.dbc import BusLayout
from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.health import Fault
from bsn_edge.alerts.serial_codec import encode_frame


@dataclass
class SenderStats:
    sent: int = 0
    errors: int = 0
    full: int = 0
    reconnects: int = 0
    last_error: str = ""
    log_errors: int = 0          # the sender's log (``--can-log``) failed: it is given up, the bus goes on
    log_error: str = ""


@dataclass(frozen=True)
class Sent:
    """What one :meth:`Sender.send` did, as the sender saw it: whether the cycle went out, and the faults it
    met on the way, by :class:`Fault` (a failed transmit, a full transmit queue, the sender's log given up:
    the last can happen to a cycle that went out). True when the cycle went out."""

    ok: bool
    faults: dict[Fault, int] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.ok


class Encoder(Protocol):
    """How an AlertFrame becomes the frames a transport carries: ``(id, payload)`` pairs. The encoding is
    the bus protocol's (:class:`~bsn_edge.alerts.can_codec.CanEncoder`: the DBC's hazard and status
    frames, with their counters and CRCs); a transport only carries what it is given."""

    def encode(self, frame: AlertFrame, messages: tuple[str, ...] | None = None) -> list[tuple[int, bytes]]: ...


class Sender(ABC):
    """Base class: ``send`` never raises; ``close`` is idempotent; usable as a context manager. A sender
    is given its encoder (the protocol's, :class:`CanEncoder`, unless told otherwise) and owns only the
    transport: a subclass fills :meth:`_send`. A subclass with a ``scheme`` is an output a user can name
    (``SCHEME:TARGET``, :func:`open_sender`): it registers itself in :data:`SENDERS` and opens from its
    target with :meth:`from_target`."""

    name = "sender"
    scheme: ClassVar[str] = ""       # how a user names this output; "" for a sender no one names
    tx_fault = Fault.TX_ERRORS       # what a failed send counts as

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.scheme:
            SENDERS[cls.scheme] = cls

    @classmethod
    def from_target(cls, target: str, encoder: Encoder | None, log_path: str | None, bus: BusConfig) -> Sender:
        """The sender of ``SCHEME:TARGET``'s target, with the vehicle file's ``bus`` settings; ``ValueError``
        for a target it cannot mean (a subclass with a ``scheme`` fills this)."""
        raise NotImplementedError(f"{cls.__name__} is not opened by name")

    def __init__(self, encoder: Encoder | None = None) -> None:
        self.stats = SenderStats()
        self._met: dict[Fault, int] = {}     # the faults met by the send in progress
        self.encoder: Encoder = encoder if encoder is not None else CanEncoder()
        self._closed = False

    @abstractmethod
    def _send(self, frames: list[tuple[int, bytes]]) -> None: ...

    def _close(self) -> None:  # noqa: B027 - optional hook
        pass

    def send(self, frame: AlertFrame, messages: tuple[str, ...] | None = None) -> Sent:
        """Encode and send one cycle (``messages``: the ones due, by name; None: every one); what it did and
        the faults it met (counted in ``stats`` too). Never raises."""
        self._met = {}
        if self._closed:
            self._failed("sender is closed")
            return Sent(False, dict(self._met))
        try:
            self._send(self.encoder.encode(frame, messages))
        except Exception as e:  # a transmit failure must never stop the loop
            self._failed(f"{type(e).__name__}: {e}")
            return Sent(False, dict(self._met))
        self.stats.sent += 1
        return Sent(True, dict(self._met))

    def _met_fault(self, fault: Fault) -> None:
        """Count ``fault`` against the send in progress (a subclass's hook for what its transport meets)."""
        self._met[fault] = self._met.get(fault, 0) + 1

    def _failed(self, why: str) -> None:
        self.stats.errors += 1
        self.stats.last_error = why
        self._met_fault(self.tx_fault)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self._close()
            except Exception as e:
                self.stats.last_error = f"close: {type(e).__name__}: {e}"

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def transmit_buffer_full(e: Exception) -> bool:
    """Whether a python-can send error is the transmit queue being full (the bus is saturated or
    unplugged: frames are dropped, not the sender broken). python-can gives no type for it: the
    kernel's ENOBUFS as ``error_code``, or socketcan's send timeout, "Transmit buffer full"."""
    return getattr(e, "error_code", None) == errno.ENOBUFS or "transmit buffer full" in str(e).lower()


BLF_BLOCK_BYTES = 1024


# the outputs a user can name, by scheme: every Sender subclass with a ``scheme`` (a new bus is one class)
SENDERS: dict[str, type[Sender]] = {}


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


class UdpSender(Sender):
    """The bus's frames in UDP datagrams, for a driving stack on a PC (``udp:HOST:PORT``; an IPv6 host in
    brackets, ``udp:[::1]:9000``). One datagram a cycle: :data:`UDP_MAGIC`, then each frame as its send time
    (float64, seconds since the epoch, big-endian), its CAN id (uint32 big-endian), its length (uint8) and
    its bytes: the same frames, counters and CRCs a CAN bus carries, which the DBC decodes. A send the
    network refuses (no route, nobody listening: the ICMP answer of the datagram before, a full socket
    buffer) is a failed send, counted as the other buses count theirs; the socket never blocks the loop."""

    name = "udp"
    scheme = "udp"

    def __init__(self, host: str, port: int, encoder: Encoder | None = None) -> None:
        super().__init__(encoder)
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)   # a name that does not resolve raises
        family, kind, proto, _, address = infos[0]
        self.address: tuple[Any, ...] = tuple(address)
        self.sock = socket.socket(family, kind, proto)
        self.sock.setblocking(False)
        self.sock.connect(self.address)           # connected: the network's refusals come back as errors

    def _send(self, frames: list[tuple[int, bytes]]) -> None:
        now = time.time()
        payload = UDP_MAGIC + b"".join(UDP_FRAME_HEAD.pack(now, fid, len(data)) + data for fid, data in frames)
        try:
            self.sock.send(payload)
        except (BlockingIOError, InterruptedError):
            self.stats.full += 1
            self._met_fault(Fault.TX_FULL)
            raise

    def _close(self) -> None:
        self.sock.close()

    @classmethod
    def from_target(cls, target: str, encoder: Encoder | None, log_path: str | None, bus: BusConfig) -> Sender:
        if log_path:
            raise ValueError("a UDP output keeps no CAN log")
        host, sep, port = target.rpartition(":")
        host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
        if not (sep and host and port.isdigit() and 0 < int(port) < 65536):
            raise ValueError(f"udp:{target}: give udp:HOST:PORT, e.g. udp:192.168.1.20:9000")
        return cls(host, int(port), encoder)


UDP_MAGIC = b"BSN1"      # a UdpSender datagram's first bytes: the layout's name and version
UDP_FRAME_HEAD = struct.Struct(">dIB")     # a frame's send time, CAN id and length, before its bytes


def udp_frames(datagram: bytes) -> list[tuple[float, int, bytes]]:
    """A :class:`UdpSender` datagram read back: ``(time, id, bytes)`` of each frame; ``ValueError`` for one
    that is not of that layout (another magic, a frame cut short)."""
    if datagram[:len(UDP_MAGIC)] != UDP_MAGIC:
        raise ValueError(f"not a bsn-run datagram (it starts {datagram[:4]!r}, not {UDP_MAGIC!r})")
    out, k = [], len(UDP_MAGIC)
    while k < len(datagram):
        if k + UDP_FRAME_HEAD.size > len(datagram):
            raise ValueError(f"a frame cut short at byte {k}")
        t, fid, n = UDP_FRAME_HEAD.unpack_from(datagram, k)
        k += UDP_FRAME_HEAD.size
        if k + n > len(datagram):
            raise ValueError(f"a frame of {n} bytes cut short at byte {k}")
        out.append((t, fid, datagram[k:k + n]))
        k += n
    return out


def open_sender(output: str, encoder: Encoder | None = None, log_path: str | None = None,
                bus: BusConfig | None = None, layout: BusLayout | None = None) -> Sender:
    """The sender of ``SCHEME:TARGET`` (``can:socketcan:can0``, ``serial:/dev/ttyUSB0``) with ``encoder``
    (by default the protocol's for the sector ``layout``, the default layout when None) and the vehicle file's
    ``bus`` settings (baud rate, timeouts); ``ValueError`` naming the valid schemes for another."""
    scheme, target = parse_output(output)
    if encoder is None and layout is not None:
        encoder = CanEncoder(layout)
    return SENDERS[scheme].from_target(target, encoder, log_path, bus or BusConfig())


def parse_output(output: object) -> tuple[str, str]:
    """``SCHEME:TARGET`` split, the scheme one of :data:`SENDERS`; ``ValueError`` naming the valid schemes."""
    scheme, _, target = output.partition(":") if isinstance(output, str) else ("", "", "")
    if scheme not in SENDERS or not target:
        raise ValueError(f"output {output!r}: give SCHEME:TARGET with SCHEME one of {', '.join(sorted(SENDERS))}")
    return scheme, target
