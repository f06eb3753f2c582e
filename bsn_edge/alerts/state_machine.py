"""Hazard levels as data and a pure state machine that takes the time from its caller.

Per sector: exponential smoothing of the raw score (time constant in seconds, so the frame
rate does not change the behaviour), hysteresis (a level turns on above its ``on`` threshold
and off below its ``off``), a creation delay (the score must stay above ``on`` this long) and
a minimum hold (a level stays at least this long). Tests just loop over timestamps.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field
from enum import IntEnum

from bsn_edge.config_toml import check_fields, setting

EPS_S = 1e-9  # timestamps from a caller carry float noise; a hold of 1 s ends at 0.9999999999 s too


class Level(IntEnum):
    NONE = 0
    CAUTION = 1
    WARNING = 2


@dataclass(frozen=True)
class LevelRule:
    """When a level starts and ends (scores in [0, 1], times in seconds)."""

    on: float = setting(MISSING, 0.05, 0.9)       # at most 0.9: a smoothed score must be able to reach it
    off: float = setting(MISSING, 0.0, 0.9)
    delay_s: float = setting(MISSING, 0.0, 5.0, "s")
    hold_s: float = setting(MISSING, 0.0, 10.0, "s")

    def __post_init__(self) -> None:
        check_fields(self)
        if not 0 <= self.off < self.on <= 1:
            raise ValueError(f"need 0 <= off < on <= 1, got on={self.on} off={self.off}")
        if self.delay_s < 0 or self.hold_s < 0:
            raise ValueError("delay and hold must be >= 0 s")


@dataclass(frozen=True)
class AlertConfig:
    tau_s: float = setting(0.3, 0.0, 2.0, "s")   # smoothing time constant
    caution: LevelRule = field(default_factory=lambda: LevelRule(on=0.25, off=0.15, delay_s=0.2, hold_s=1.0))
    warning: LevelRule = field(default_factory=lambda: LevelRule(on=0.6, off=0.45, delay_s=0.1, hold_s=1.5))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.warning.on <= self.caution.on:
            raise ValueError("a WARNING must need a higher score than a CAUTION")


@dataclass
class SectorState:
    """The state of one sector; ``update`` is the whole machine."""

    cfg: AlertConfig = field(default_factory=AlertConfig)
    smoothed: float = 0.0
    level: Level = Level.NONE
    _t: float | None = None
    _since: float = 0.0                       # when the current level began
    _above: dict[Level, float | None] = field(default_factory=lambda: {Level.CAUTION: None, Level.WARNING: None})

    def _rule(self, level: Level) -> LevelRule:
        return self.cfg.caution if level == Level.CAUTION else self.cfg.warning

    def update(self, t: float, score: float) -> tuple[float, Level]:
        """Feed the raw ``score`` observed at time ``t`` (seconds, non-decreasing)."""
        if self._t is None:
            self.smoothed, self._t, self._since = score, t, t
        else:
            dt = t - self._t
            if dt < 0:
                raise ValueError(f"time went backwards: {t} after {self._t}")
            a = 1.0 if self.cfg.tau_s == 0 else 1.0 - math.exp(-dt / self.cfg.tau_s)
            self.smoothed += a * (score - self.smoothed)
            self._t = t
        s = self.smoothed
        for lv in (Level.CAUTION, Level.WARNING):
            if s >= self._rule(lv).on:
                if self._above[lv] is None:
                    self._above[lv] = t
            else:
                self._above[lv] = None
        # the highest level whose score has been above its 'on' for its creation delay
        target = self.level
        for lv in (Level.WARNING, Level.CAUTION):
            since = self._above[lv]
            if lv > self.level and since is not None and t - since >= self._rule(lv).delay_s - EPS_S:
                target = lv
                break
        if target == self.level and self.level > Level.NONE:
            rule = self._rule(self.level)
            if s < rule.off and t - self._since >= rule.hold_s - EPS_S:
                target = Level(self.level - 1)
                # step down only as far as the lower level still holds
                while target > Level.NONE and s < self._rule(target).off:
                    target = Level(target - 1)
        if target != self.level:
            self.level, self._since = target, t
        return self.smoothed, self.level
