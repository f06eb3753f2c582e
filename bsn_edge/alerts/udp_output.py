"""``udp:HOST:PORT``: the bus's frames in UDP datagrams, for a driving stack on a PC."""

from __future__ import annotations

import socket
import struct
import time
from typing import Any

from bsn_edge.alerts.bus_config import BusConfig
from bsn_edge.alerts.health import Fault
from bsn_edge.alerts.senders import Encoder, Sender


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
