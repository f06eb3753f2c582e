"""A run of ``bsn-run`` read back: its frame log (and summary), the level onsets, the states and the latency.

The frame log's lines are :class:`~bsn_edge.runtime.frame_record.FrameRecord`'s, read back by it; a line that
is not one (cut by a kill, damaged on disk) is kept as a :class:`Damage` with its line number, and the rest
of the drive is read on.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.alerts.sectors import SECTORS
from bsn_edge.alerts.state_machine import Level
from bsn_edge.runtime.frame_record import FrameRecord
from bsn_edge.runtime.stages import STAGES
from bsn_edge.user_file import read_user_file

PERCENTILES = (50, 95, 99)


@dataclass(frozen=True)
class Onset:
    """A sector's level rising (NONE -> CAUTION, CAUTION -> WARNING or NONE -> WARNING) at a frame."""

    sector: str
    level: str
    t: float
    frame: int
    distance_m: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"sector": self.sector, "level": self.level, "t": self.t, "frame": self.frame,
                "distance_m": self.distance_m}


@dataclass(frozen=True)
class Damage:
    """A line of the log that could not be read: its number (from 1) and why."""

    line: int
    why: str


@dataclass
class Drive:
    """What a run wrote: its frames in order, the lines that could not be read, and its summary (if given)."""

    records: list[FrameRecord]
    damage: list[Damage] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)
    names: tuple[str, ...] = SECTORS     # the run's sectors, left to right (its summary's layout)

    @cached_property
    def onsets(self) -> list[Onset]:
        """Every level onset, in the order of the frames (a frame without levels changes nothing); worked out
        once, the page, the bus check and the thumbnails all read it."""
        out: list[Onset] = []
        last = [Level.NONE] * len(self.names)
        for rec in self.records:
            if rec.hazard is None:
                continue
            for k, (name, s) in enumerate(zip(self.names, rec.hazard.sectors, strict=True)):
                if s.level > last[k]:
                    out.append(Onset(name, s.level.name, rec.t, rec.frame, s.distance_m))
                last[k] = s.level
        return out

    def latency(self) -> dict[str, dict[str, float]]:
        """Per stage (and ``total``, the frame's latency): p50 / p95 / p99 in milliseconds, over the frames
        that went through it."""
        out: dict[str, dict[str, float]] = {}
        for stage in (*STAGES, "total"):
            values = [r.latency_ms if stage == "total" else r.stage_ms.get(stage) for r in self.records]
            got = np.array([v for v in values if v is not None and math.isfinite(v)], np.float64)
            if got.size:
                out[stage] = {f"p{p}": round(float(np.percentile(got, p)), 3) for p in PERCENTILES}
        return out

    def states(self) -> list[tuple[float, float, str]]:
        """The system state over the drive as spans ``(from t, to t, state)``, from the frames that carried one."""
        spans: list[tuple[float, float, str]] = []
        for rec in self.records:
            if rec.status is None:
                continue
            state = rec.status.state.name
            if spans and spans[-1][2] == state:
                spans[-1] = (spans[-1][0], rec.t, state)
            else:
                spans.append((rec.t, rec.t, state))
        return spans

    def camera(self) -> list[tuple[float, float, str, list[str]]]:
        """Where the camera-health check raised a reason: spans ``(from t, to t, reason, unseen sectors)``."""
        spans: list[tuple[float, float, str, list[str]]] = []
        for rec in self.records:
            v = rec.visibility
            if v is None:
                continue
            unseen = [s for s, u in zip(self.names, v.unseen, strict=True) if u]
            if spans and spans[-1][2] == v.reason.name and spans[-1][3] == unseen and rec.t - spans[-1][1] < 1.0:
                spans[-1] = (spans[-1][0], rec.t, v.reason.name, unseen)
            else:
                spans.append((rec.t, rec.t, v.reason.name, unseen))
        return spans

    def faults(self) -> list[tuple[float, int, str]]:
        """Each frame that had a fault: ``(t, frame, fault)``."""
        return [(r.t, r.frame, r.fault.value) for r in self.records if r.fault is not None]

    def to_dict(self) -> dict[str, Any]:
        """Every number the report shows."""
        return {"frames": len(self.records), "valid_frames": sum(r.hazard is not None for r in self.records),
                "damaged_lines": [vars(d) for d in self.damage],
                "onsets": [o.to_dict() for o in self.onsets], "latency_ms": self.latency(),
                "states": [{"from_t": a, "to_t": b, "state": s} for a, b, s in self.states()],
                "faults": [{"t": t, "frame": f, "fault": k} for t, f, k in self.faults()],
                "camera": [{"from_t": a, "to_t": b, "reason": r, "unseen": u} for a, b, r, u in self.camera()],
                "calibration": calibration(self.summary), "identity": identity(self.summary),
                "on_bus": {"states_s": _seconds(self.summary.get("states_s")),
                           "why_s": {k: _seconds(v) for k, v in _mapping(self.summary.get("why_s")).items()}}}


def _mapping(x: Any) -> dict[str, Any]:
    """``x`` when it is a JSON object, else empty (a summary's field of the wrong shape is left out)."""
    return {str(k): v for k, v in x.items()} if isinstance(x, dict) else {}


def _seconds(x: Any) -> dict[str, float]:
    """The finite numbers of a JSON object of seconds by name (anything else left out)."""
    return {k: float(v) for k, v in _mapping(x).items()
            if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)}


def read_drive(log: str | Path, summary: str | Path | None = None) -> Drive:
    """The run whose frame log is ``log`` (and summary ``summary``). ``FileNotFoundError`` for a missing file,
    ``ValueError`` for a log of which no line could be read or a summary that is not a run's."""
    log = Path(log)
    if not log.is_file():
        raise FileNotFoundError(f"frame log {log} not found")
    about = _summary(summary) if summary is not None else {}
    names: tuple[str, ...] | None = sector_names(about) if summary is not None else None
    records, damage = [], []
    with log.open("rb") as f:
        for n, raw in enumerate(f, 1):
            try:
                line = raw.decode("utf-8")
                if not line.strip():
                    continue
                d = json.loads(line)
                if names is None and isinstance(d, dict) and isinstance(d.get("levels"), list):
                    names = unnamed(len(d["levels"]))      # no summary to name them: the first frame's count
                records.append(FrameRecord.from_json(d, names or SECTORS))
            except (UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError, RecursionError,
                    OverflowError) as e:
                damage.append(Damage(n, f"{type(e).__name__}: {e}"[:200]))
    if not records:
        raise ValueError(f"{log}: no line is a frame of bsn-run's log ({len(damage)} unreadable)")
    return Drive(records, damage, about, names or SECTORS)


def _summary(summary: str | Path) -> dict[str, Any]:
    """A run's summary read; ``FileNotFoundError`` or ``ValueError`` naming it when it is not one."""
    p = Path(summary)
    if not p.is_file():
        raise FileNotFoundError(f"summary {p} not found")
    try:
        about = json.loads(read_user_file(p, "JSON").decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise ValueError(f"{p}: not a run's summary ({e})") from None
    if not isinstance(about, dict) or "frames" not in about:
        raise ValueError(f"{p}: not a run's summary (bsn-run --summary writes one)")
    return about


def unnamed(count: int) -> tuple[str, ...]:
    """The sectors of a log read without its summary: the default layout's when there are as many, else
    ``SECTOR1``... left to right."""
    return SECTORS if count == len(SECTORS) else tuple(f"SECTOR{k + 1}" for k in range(count))


def sector_names(summary: dict[str, Any]) -> tuple[str, ...]:
    """The run's sectors, left to right, from its summary's resolved settings (``settings.sectors.layout``); the
    default layout's for a run without a summary or one written before the layout was a setting. ``ValueError``
    for a layout the settings would refuse."""
    from bsn_edge.alerts.sectors import SectorConfig

    sectors = _mapping(_mapping(summary.get("settings")).get("sectors"))
    if "layout" not in sectors:
        return SECTORS
    try:
        return SectorConfig(layout=sectors["layout"]).names
    except (ValueError, TypeError) as e:
        raise ValueError(f"the summary's settings.sectors.layout is no layout: {e}") from None


def calibration(summary: dict[str, Any]) -> dict[str, Any]:
    """When the first guess was used, when calibration converged and the camera it settled on (from the
    summary; empty without one)."""
    cam = summary.get("camera") or {}
    report = cam.get("calibration") or {}
    return {"source": report.get("source"), "converged_at": report.get("converged_at"),
            "first_guess": cam.get("first_guess"), "mounting": cam.get("mounting"),
            "intrinsics": cam.get("intrinsics"), "hood": cam.get("hood")}


def identity(summary: dict[str, Any]) -> dict[str, Any]:
    """Which model, settings, source and machine the run was."""
    model = summary.get("model") or {}
    return {"model": {k: model.get(k) for k in ("variant", "graph_sha256", "config_digest", "signer", "authentic",
                                                "quantization", "threshold")},
            "settings_digest": summary.get("settings_digest"), "source": summary.get("source"),
            "machine": summary.get("machine")}
