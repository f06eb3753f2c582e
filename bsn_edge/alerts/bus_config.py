"""The buses the alerts go out on, how a send may fail, and how often each message goes: the vehicle file's
``[bus]`` and ``[messages]`` tables.

``[messages]`` is the bus's table of messages and their rates (as openpilot's ``cereal/services.py`` keeps
one): each message every so many send cycles (``runtime.cycle_s``), never less often than once a second.
"""

from __future__ import annotations

from dataclasses import dataclass

from bsn_edge.alerts.can_codec import HAZARD, STATUS
from bsn_edge.config_toml import check_fields, setting

MAX_MESSAGE_PERIOD_S = 1.0      # a receiver's deadline for the status is about a second: none may go slower


@dataclass(frozen=True)
class BusConfig:
    """Where the alerts go (``bsn-run --can`` and ``--serial`` override ``can`` and ``serial``) and how a
    send may fail: the timeouts of one send, how soon a serial port that went away is tried again, and how
    long every send of a bus may fail before it is down (the status then says DEGRADED on the others)."""

    can: str = ""                # IFACE:CHANNEL (socketcan:can0, virtual:test); "" for none
    serial: str = ""             # a port or pyserial URL (/dev/ttyUSB0, loop://); "" for none
    outputs: tuple[str, ...] = ()   # more outputs, each SCHEME:TARGET (udp:192.168.1.20:9000, can:..., serial:...)
    serial_baud: int = setting(115200, 1200, 4_000_000, "baud")
    can_timeout_s: float = setting(0.01, 0.001, 0.1, "s")
    serial_write_timeout_s: float = setting(0.05, 0.001, 0.5, "s")
    serial_retry_s: float = setting(1.0, 0.1, 10.0, "s")
    down_after_s: float = setting(1.0, 0.1, 5.0, "s")

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.can, str) or not isinstance(self.serial, str):
            raise ValueError("bus.can and bus.serial are names (text), \"\" for none")
        if self.can and ":" not in self.can.strip(":"):
            raise ValueError(f"bus.can = {self.can!r} must be IFACE:CHANNEL, e.g. socketcan:can0")
        from bsn_edge.alerts.senders import parse_output

        for o in self.outputs:
            try:
                parse_output(o)
            except ValueError as e:
                raise ValueError(f"bus.outputs: {e}") from None


@dataclass(frozen=True)
class MessageRates:
    """Each message of the bus every so many send cycles."""

    hazard_every: int = setting(1, 1, 10, "cycles")
    status_every: int = setting(1, 1, 10, "cycles")

    def __post_init__(self) -> None:
        check_fields(self)

    def every(self) -> dict[str, int]:
        """By message name (the DBC's), in the order they go out within a cycle."""
        return {HAZARD: self.hazard_every, STATUS: self.status_every}

    def check(self, cycle_s: float) -> None:
        """``ValueError`` when a message would go out less often than :data:`MAX_MESSAGE_PERIOD_S`."""
        for name, every in self.every().items():
            if every * cycle_s > MAX_MESSAGE_PERIOD_S + 1e-9:
                raise ValueError(f"{name} every {every} cycles of {cycle_s:g} s is {every * cycle_s:g} s apart; "
                                 f"a message goes at least once every {MAX_MESSAGE_PERIOD_S:g} s")
