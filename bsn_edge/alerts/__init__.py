"""Masks -> sectors -> smoothing -> CAN / serial.

``sectors`` turns a blind-spot mask and depth into LEFT / CENTRE / RIGHT readings;
``state_machine`` smooths them into levels with hysteresis, delays and holds (time from the
caller); ``health`` tracks the system state and fault counters; ``senders`` put the result on
a CAN bus (DBC ``bsn_alerts.dbc``, alive counter and CRC in every frame) or a serial line.
"""

from bsn_edge.alerts.frame import AlertFrame, Hazard, SectorAlert
from bsn_edge.alerts.health import Fault, Health, HealthConfig, Status, SystemState
from bsn_edge.alerts.sectors import SECTORS, SectorConfig, SectorGeometry, SectorReading
from bsn_edge.alerts.state_machine import AlertConfig, Level, LevelRule, SectorState

__all__ = ["SECTORS", "AlertConfig", "AlertFrame", "Fault", "Hazard", "Health", "HealthConfig", "Level", "LevelRule",
           "SectorAlert", "SectorConfig", "SectorGeometry", "SectorReading", "SectorState", "Status", "SystemState"]
