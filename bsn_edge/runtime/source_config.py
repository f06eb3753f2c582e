"""How the runtime watches its source and how online calibration shares the cores: the vehicle file's
``[source]`` and ``[calibration]`` tables."""

from __future__ import annotations

from dataclasses import dataclass

from bsn_edge.config_toml import check_fields, setting
from bsn_edge.runtime.live_source import Reconnect
from bsn_edge.runtime.priority import NICE_RANGE


@dataclass(frozen=True)
class SourceConfig:
    """A camera or stream that delivers nothing for ``stall_s`` is lost (``bsn-run --stall`` overrides it): the
    bus says UNAVAILABLE and it is reopened after ``reconnect_first_s``, the wait doubling up to
    ``reconnect_max_s``, until ``give_up_s`` without a frame ends the run (0: never)."""

    stall_s: float = setting(Reconnect.stall_s, 0.1, 60.0, "s")
    reconnect_first_s: float = setting(Reconnect.first_s, 0.01, 10.0, "s")
    reconnect_max_s: float = setting(Reconnect.max_s, 0.1, 60.0, "s")
    give_up_s: float = setting(Reconnect.give_up_s, 0.0, 3600.0, "s")

    def __post_init__(self) -> None:
        check_fields(self)
        if self.reconnect_first_s > self.reconnect_max_s:
            raise ValueError(f"source.reconnect_first_s ({self.reconnect_first_s:g}) must not be over "
                             f"source.reconnect_max_s ({self.reconnect_max_s:g})")

    def reconnect(self) -> Reconnect:
        """The reconnect policy a live source is opened with."""
        return Reconnect(self.stall_s, self.reconnect_first_s, self.reconnect_max_s, self.give_up_s)


@dataclass(frozen=True)
class CalibrationConfig:
    """Online calibration of a camera without a mounting: about ``frames_per_s`` frames a second go to its
    estimator, on a thread ``nice`` steps below the model's priority, so it never takes the model's cores."""

    frames_per_s: float = setting(12.5, 1.0, 30.0, "frames/s")
    nice: int = setting(10, *NICE_RANGE)

    def __post_init__(self) -> None:
        check_fields(self)
