"""The buses a run sends on: named by the user (flags, else the vehicle file's ``[bus]``), opened each within a
deadline, and their last word (UNAVAILABLE, then closed) whatever ends the run or refuses it."""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, TypeVar

from bsn_edge.alerts.bus_config import BusConfig
from bsn_edge.alerts.dbc import BusLayout
from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.senders import Sender, open_sender

T = TypeVar("T")

LOG_CHANNEL = "bsn-can-log"     # the virtual bus a CAN log is written from when no CAN bus is named
OPEN_DEADLINE_S = 1.0     # a bus or CAN log that has not opened by then never will (a FIFO nobody reads, a hung mount)


def open_within(opener: Callable[[], T], seconds: float, what: str) -> T:
    """``opener()`` on a thread of its own, waited for ``seconds`` at most: its result or its exception;
    ``TimeoutError`` naming ``what`` when it is still blocked (the thread is left behind, a daemon)."""
    result: list[Any] = []

    def attempt() -> None:
        try:
            result.append((True, opener()))
        except BaseException as e:  # handed to the caller's thread
            result.append((False, e))

    t = threading.Thread(target=attempt, name="bsn-open", daemon=True)
    t.start()
    t.join(seconds)
    if not result:
        raise TimeoutError(f"{what} did not open within {seconds:g} s (a FIFO nobody reads, a hung disk or mount?)")
    ok, value = result[0]
    if not ok:
        raise value
    return value


@dataclass(frozen=True)
class BusOutput:
    """One bus to open: ``SCHEME:TARGET`` (:func:`~bsn_edge.alerts.senders.open_sender`'s), the CAN log written
    beside it, and how a message names it."""

    output: str
    log: str | None
    what: str


def bus_outputs(can: str | None, serial: str | None, can_log: str | None = None,
                bus: BusConfig | None = None, more: tuple[str, ...] = ()) -> list[BusOutput]:
    """The buses named: ``can`` (``IFACE:CHANNEL``) and ``serial`` (a port or pyserial URL), each else the
    vehicle file's (``bus``); a CAN log alone is written from a virtual bus; then the vehicle file's
    ``bus.outputs`` and ``more`` (``bsn-run --output``), each ``SCHEME:TARGET``, in that order. ``ValueError``
    for a CAN bus not given as ``IFACE:CHANNEL``."""
    bus = bus or BusConfig()
    can, serial = can or bus.can or None, serial or bus.serial or None
    out: list[BusOutput] = []
    if can or can_log:
        named = can or f"virtual:{LOG_CHANNEL}"
        iface, _, channel = named.partition(":")
        if not (iface and channel):
            raise ValueError(f"--can needs IFACE:CHANNEL, got {named!r}")
        what = f"CAN interface {iface!r} channel {channel!r}" + (f" with its log {can_log}" if can_log else "")
        out.append(BusOutput(f"can:{named}", can_log, what))
    if serial:
        out.append(BusOutput(f"serial:{serial}", None, f"serial port {serial!r} at {bus.serial_baud} baud"))
    out += [BusOutput(o, None, f"output {o!r}") for o in (*bus.outputs, *more)]
    return out


def open_senders(outputs: Iterable[BusOutput], bus: BusConfig | None = None,
                 deadline_s: float = OPEN_DEADLINE_S, layout: BusLayout | None = None) -> list[Sender]:
    """A sender for each output, each opened within ``deadline_s`` and encoding for the sector ``layout`` (the
    default layout's when None); ``ValueError`` naming the one that cannot be opened, the ones already open
    having said UNAVAILABLE and closed (:func:`last_word`)."""
    bus = bus or BusConfig()
    senders: list[Sender] = []
    try:
        for o in outputs:
            try:
                senders.append(open_within(functools.partial(open_sender, o.output, log_path=o.log, bus=bus,
                                                             layout=layout),
                                           deadline_s, o.what))
            except Exception as e:
                raise ValueError(f"cannot open {o.what}: {type(e).__name__}: {e}") from None
    except BaseException:
        last_word(senders)       # a second output that cannot be opened (or Ctrl-C meanwhile)
        raise
    return senders


def last_word(senders: Iterable[Sender], t: float = 0.0) -> None:
    """UNAVAILABLE on every bus, then each closed: what a run that is refused, stopped or ended says last
    (closing is idempotent, so a sender already closed is only counted as failing to send)."""
    frame = AlertFrame.unavailable(t)
    for s in senders:
        s.send(frame)
        s.close()
