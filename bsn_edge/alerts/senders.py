"""Senders: where AlertFrames go. A sender that cannot send says so: every failure is counted in
``stats`` and reported by the send that met it (:class:`Sent`, which the send cycle adds to the status
message's fault counters), retried with back-off where that helps, and never raised into the caller's loop."""

from __future__ import annotations

import errno
import functools
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

from bsn_edge.alerts.bus_config import BusConfig
from bsn_edge.alerts.can_codec import CanEncoder
from bsn_edge.alerts.dbc import BusLayout
from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.health import Fault


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




# the outputs a user can name, by scheme: every Sender subclass with a ``scheme`` (a new bus is one class)
SENDERS: dict[str, type[Sender]] = {}


OUTPUT_MODULE_SUFFIX = "_output"     # bsn_edge/alerts/<name>_output.py: an output a user can name


@functools.cache
def load_outputs() -> dict[str, type[Sender]]:
    """Every output the package has: each module ``bsn_edge/alerts/*_output.py`` imported (its sender registers
    itself, :meth:`Sender.__init_subclass__`), so a new output is one new file. The transports' own libraries
    (python-can, pyserial) are imported when a sender opens, not here."""
    import importlib
    import pkgutil

    import bsn_edge.alerts as package

    for m in pkgutil.iter_modules(package.__path__):
        if m.name.endswith(OUTPUT_MODULE_SUFFIX):
            importlib.import_module(f"{__package__}.{m.name}")      # a module of this package, as the layers see it
    return SENDERS


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
    load_outputs()
    scheme, _, target = output.partition(":") if isinstance(output, str) else ("", "", "")
    if scheme not in SENDERS or not target:
        raise ValueError(f"output {output!r}: give SCHEME:TARGET with SCHEME one of {', '.join(sorted(SENDERS))}")
    return scheme, target
