"""What a run of the runtime did: :class:`RunSummary`, written as ``bsn-run --summary`` and printed.

Fields of the JSON (:meth:`RunSummary.to_json`), in the order written: ``frames`` (read from the source),
``valid_frames`` (with a valid inference), ``dropped`` (a live source's frames the loop had no time for),
``before_start`` (replaced before the loop first asked), ``overlap``, ``in_flight`` (how reading and inference
ran), ``seconds``, ``fps`` (frames a second of processing), ``p50_ms``, ``p95_ms``, ``p99_ms`` (latency),
``wait_ms`` (frames waiting for the model, same percentiles), ``stage_ms`` and ``stage_share`` (per stage of the
way, :data:`~bsn_edge.runtime.stages.STAGES`: decode, preprocess, visibility, inference, postprocess, send,
outputs), ``faults`` (the counters, by :class:`~bsn_edge.alerts.health.Fault` name), ``cycles_sent``,
``stall_cycles`` (of them, sent by the stall watch while a file's loop was stuck on a frame), ``states_s``
(seconds of cycles on the bus in each state: OK, CALIBRATING, DEGRADED, UNAVAILABLE; the run's last word,
UNAVAILABLE whatever ended it, not counted), ``why_s`` (the same seconds by state and reason: a stall, no valid
inference yet, the frame rate under the floor, an output down, a fault, the camera, levels from an assumed camera
while calibrating), ``senders`` (per sender: sent, errors, ...), ``senders_down`` (senders that could not send at
the end), ``source_failure`` (why the source ended early, or null), ``stopped`` (by a signal or the caller),
``heartbeat_error``, ``camera`` (intrinsics, mounting, calibration report, hood: share of the rows, spread,
columns agreeing, arch; null while still looked for), ``visibility`` (what the camera-health check raised: frames
and seconds per reason, and its stretches), ``maps_written``, ``cpu`` (``cpu_ms_per_frame``: the process's CPU,
every thread, per frame from the 20th to the last; ``cores_busy``: CPU seconds a second over those frames),
``sinks`` (per output: written, dropped, failure), ``model`` (variant, size, threshold, quantization, kernels,
self-test, signer, authentic, trust note, graph and config digests); ``bsn-run`` adds ``signal``, ``source``
(what it read) and ``machine`` (CPU, its int8 instruction sets, cores, Python)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from bsn_edge.alerts.health import Fault


def machine() -> dict[str, Any]:
    """The machine a run ran on, for its summary: the CPU's name, the int8 instruction sets the model's
    speed depends on, cores and Python."""
    import os
    import platform

    cpu, flags = platform.processor() or platform.machine(), set()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as info:
            for line in info:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and cpu == (platform.processor() or platform.machine()):
                    cpu = value.strip()
                elif key.strip() == "flags":
                    flags = set(value.split())
                    break
    except OSError:
        pass
    isa = [name for name, flag in (("AVX2", "avx2"), ("AVX-512", "avx512f"), ("VNNI", "avx512_vnni"),
                                   ("AVX-VNNI", "avx_vnni"), ("AMX", "amx_int8")) if flag in flags]
    return {"cpu": cpu, "isa": isa, "cores": os.cpu_count(), "python": platform.python_version()}


@dataclass(frozen=True)
class ModelSummary:
    variant: str
    size: tuple[int, int]
    threshold: float
    quantization: str
    kernels: str
    self_test: dict[str, float]
    signer: str
    authentic: bool
    trust_note: str
    graph_sha256: str = ""        # the sealed card's digest of the graph run
    config_digest: str = ""       # of the training config it came from


@dataclass(frozen=True)
class SinkSummary:
    written: int
    dropped: int
    failure: dict[str, Any] | None


@dataclass(frozen=True)
class RunSummary:
    frames: int
    valid_frames: int
    dropped: int
    before_start: int
    overlap: bool
    in_flight: int
    seconds: float
    fps: float
    latency_ms: dict[str, float]          # written flat: p50_ms, p95_ms, p99_ms
    wait_ms: dict[str, float]
    stage_ms: dict[str, float]
    stage_share: dict[str, float]
    faults: dict[Fault, int]
    cycles_sent: int
    stall_cycles: int
    states_s: dict[str, float]            # seconds of cycles sent in each state, by its name
    why_s: dict[str, dict[str, float]]    # of them, by state and the reason for it
    senders: dict[str, dict[str, Any]]
    senders_down: list[str]
    source_failure: str | None
    stopped: bool
    heartbeat_error: str
    camera: dict[str, Any]
    visibility: dict[str, Any]
    maps_written: int
    cpu: dict[str, float | None] = field(default_factory=dict)   # CpuMeter.figures: CPU per frame, cores busy
    sinks: dict[str, SinkSummary] = field(default_factory=dict)
    model: ModelSummary | None = None

    def to_json(self) -> dict[str, Any]:
        """The record as ``--summary`` writes it (field names in the module's docstring)."""
        d = asdict(self)
        latency = d.pop("latency_ms")
        out: dict[str, Any] = {}
        for k, v in d.items():
            out[k] = v
            if k == "fps":
                out.update(latency)
        out["faults"] = {f.value: n for f, n in self.faults.items()}
        if self.model is not None:
            out["model"]["size"] = list(self.model.size)
        return out


def states_said(states_s: dict[str, Any], why_s: dict[str, Any]) -> str:
    """``OK 1.5 s, UNAVAILABLE 0.3 s (stall ... 0.2 s, ...)``: the summary's time in each state and, where the
    state was not OK, its reasons, the longest first ("" without any)."""
    def longest(d: dict[str, Any]) -> list[tuple[str, Any]]:
        return sorted(d.items(), key=lambda kv: -float(kv[1]))

    return ", ".join(f"{state} {float(secs):.1f} s" + (" (" + ", ".join(f"{k} {float(v):.1f} s" for k, v in why) + ")"
                                                          if (why := longest(why_s.get(state) or {})) else "")
                     for state, secs in longest(states_s))
