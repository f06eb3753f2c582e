"""The runtime's settings: :class:`RuntimeConfig`, every table of the vehicle file in one frozen record.

The settings modules (the file's reader, its schema and reference page) read this, not the loop; the loop
and the builder take it resolved.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from bsn_edge.alerts import AlertConfig, HealthConfig, SectorConfig
from bsn_edge.alerts.bus_config import BusConfig, MessageRates
from bsn_edge.config_toml import check_fields, setting
from bsn_edge.runtime.priority import NICE_RANGE
from bsn_edge.runtime.source_config import CalibrationConfig, SourceConfig
from bsn_edge.runtime.visibility import VisibilityConfig

MAX_IN_FLIGHT = 4
MAX_THREADS = 64


@dataclass(frozen=True)
class RuntimeConfig:
    """How the loop runs: the alerts' state machine, the sectors, health, the buses and their messages, the
    source's watch and reconnects, online calibration's share, the send cycle, warm-up inferences before the
    first frame, whether reading overlaps the model (:mod:`.feeder`, its thread then ``feeder_nice`` steps
    below the model's priority), and onnxruntime's threads."""

    alerts: AlertConfig = field(default_factory=AlertConfig)
    sectors: SectorConfig = field(default_factory=SectorConfig)
    health: HealthConfig = field(default_factory=HealthConfig)
    bus: BusConfig = field(default_factory=BusConfig)
    messages: MessageRates = field(default_factory=MessageRates)
    source: SourceConfig = field(default_factory=SourceConfig)
    calibration: CalibrationConfig = field(default_factory=CalibrationConfig)
    visibility: VisibilityConfig = field(default_factory=VisibilityConfig)
    cycle_s: float = setting(0.1, 0.01, 1.0, "s")
    warmup: int = setting(3, 0, 100, "inferences")
    overlap: bool = True         # decode and warp the next frame on a thread of its own while the model runs
    feeder_nice: int = setting(10, *NICE_RANGE)
    in_flight: int = setting(1, 1, MAX_IN_FLIGHT, "frames")  # each inference on a thread of its own
    threads: int = setting(0, 0, MAX_THREADS, "threads")     # onnxruntime's per inference; 0: as in_flight suits
    spin: bool = False           # idle onnxruntime threads spin-wait instead of sleeping

    def __post_init__(self) -> None:
        check_fields(self)
        if self.in_flight > 1 and not self.overlap:
            raise ValueError("more than one frame in flight needs reading overlapped with the model (overlap=True)")
        self.messages.check(self.cycle_s)

    @property
    def engine_threads(self) -> int:
        """onnxruntime intra-op threads per inference: ``threads``, else what suits ``in_flight`` on 2 cores
        (both for one frame at a time, one each for frames side by side)."""
        return self.threads or (2 if self.in_flight == 1 else 1)
