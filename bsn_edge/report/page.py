"""The report's page: one self-contained HTML file (pictures embedded, nothing fetched), and its figures.

Timelines share one time axis (the source's seconds): per sector the smoothed score against the CAUTION and
WARNING thresholds, the level as shading and the distance to the nearest blind spot; the system state and
the faults; each stage's latency. One thumbnail per level onset is cut from the overlay video when given.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.alerts.state_machine import AlertConfig
from bsn_edge.report.drive import Drive, Onset
from bsn_edge.runtime.stages import STAGES

DISTANCE_AXIS_M = 50.0      # the distance axis of a sector with no distance measured
LEVEL_COLOURS = {"CAUTION": "#f2c14e", "WARNING": "#e4572e"}
STATE_COLOURS = {"OK": "#59a14f", "CALIBRATING": "#76b7b2", "DEGRADED": "#f28e2b", "UNAVAILABLE": "#e15759"}
THUMB_WIDTH = 320
MAX_THUMBS = 40        # onsets shown with a picture; every onset is in the table and in report.json
DPI = 100


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode()


def _thresholds(summary: dict[str, Any]) -> dict[str, float]:
    alerts = (summary.get("settings") or {}).get("alerts") or {}
    default = AlertConfig()
    return {"CAUTION": float((alerts.get("caution") or {}).get("on", default.caution.on)),
            "WARNING": float((alerts.get("warning") or {}).get("on", default.warning.on))}


def _sector_axis(ax, name: str, k: int, t: np.ndarray, recs: list, on: dict[str, float]) -> None:
    """One sector's row: its smoothed score against the thresholds, its level shaded, its distance."""
    sectors = [r.hazard.sectors[k] for r in recs if r.hazard is not None]
    score = np.array([s.score for s in sectors])
    levels = [s.level.name for s in sectors]
    for level, colour in LEVEL_COLOURS.items():
        mask = np.array([lv == level for lv in levels])
        if mask.any():
            ax.fill_between(t, 0, 1, where=mask, color=colour, alpha=0.35, step="post", lw=0,
                            label=f"{level.lower()} level")
        ax.axhline(on[level], color=colour, ls="--", lw=1, label=f"{level.lower()} starts at")
    ax.plot(t, score, color="#333", lw=1, label="score (smoothed)")
    ax.set_ylim(0, 1.02)
    ax.set_ylabel(f"{name}\nscore")
    dist = np.array([np.nan if s.distance_m is None else s.distance_m for s in sectors], np.float64)
    twin = ax.twinx()
    twin.plot(t, dist, ".", ms=2, color="#4e79a7", label="distance")
    twin.set_ylabel("distance (m)", color="#4e79a7")
    if not np.isfinite(dist).any():       # no blind spot measured: the axis's range, not -0.04 to 0.04 m
        twin.set_ylim(0, DISTANCE_AXIS_M)
    if k == 0:
        ax.legend(loc="upper left", fontsize=7, ncol=3)


def timelines(drive: Drive) -> str:
    """The sectors', the state's and the latency's timelines in one picture (base64 PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    recs = [r for r in drive.records if r.hazard is not None]
    t = np.array([r.t for r in recs])
    on = _thresholds(drive.summary)
    converged = (drive.summary.get("camera") or {}).get("calibration", {}).get("converged_at") or {}
    t_conv = next((r.t for r in drive.records if r.frame + 1 == converged.get("frame")), None)
    n = len(drive.names)
    fig, axes = plt.subplots(n + 2, 1, figsize=(12, 2.0 * (n + 2)), sharex=True,
                             gridspec_kw={"height_ratios": [3] * n + [1, 3]})
    for k, (name, ax) in enumerate(zip(drive.names, axes, strict=False)):
        _sector_axis(ax, name, k, t, recs, on)
    state_ax, lat_ax = axes[n], axes[n + 1]
    spans = drive.states()
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.1
    for k, (a, b, state) in enumerate(spans):
        # each band runs to the next one's start: no white gaps, and a one-frame UNAVAILABLE a frame wide
        end = spans[k + 1][0] if k + 1 < len(spans) else b + step
        state_ax.axvspan(a, end, color=STATE_COLOURS.get(state, "#999"), lw=0)
    for tf, _, _fault in drive.faults():
        state_ax.plot([tf], [0.5], "kx", ms=5)
    state_ax.set_yticks([])
    state_ax.set_ylabel("state\nx: fault", fontsize=8)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in STATE_COLOURS.values()]
    state_ax.legend(handles, list(STATE_COLOURS), loc="upper right", fontsize=7, ncol=4)
    timed = [r for r in drive.records if r.stage_ms]
    if timed:
        tt = np.array([r.t for r in timed])
        stacks = [np.array([r.stage_ms.get(s, 0.0) for r in timed]) for s in STAGES]
        lat_ax.stackplot(tt, *stacks, labels=list(STAGES), alpha=0.8)
        lat_ax.legend(loc="upper left", fontsize=7, ncol=len(STAGES))
    lat_ax.set_ylabel("ms per frame")
    lat_ax.set_xlabel("time in the source (s)")
    if t_conv is not None:
        for ax in axes:
            ax.axvline(t_conv, color="k", lw=0.8, ls=":")
        axes[0].annotate("calibrated", (t_conv, 1.0), fontsize=7, ha="left", va="top")
    fig.tight_layout()
    out = _png(fig)
    plt.close(fig)
    return out


def latency_histogram(drive: Drive) -> str:
    """The frames' latency (decode to the bus) as a histogram with its p50 and p99 marked (base64 PNG; "" for
    a log without latencies)."""
    lat = np.array([r.latency_ms for r in drive.records if r.latency_ms is not None and np.isfinite(r.latency_ms)])
    if not lat.size:
        return ""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 2.4))
    ax.hist(lat, bins=min(60, max(10, lat.size // 10)), color="#4e79a7")
    for q, ls in ((50, "--"), (99, ":")):
        v = float(np.percentile(lat, q))
        ax.axvline(v, color="k", ls=ls, lw=1, label=f"p{q} {v:.1f} ms")
    ax.set_xlabel("latency of a frame, decode to the bus (ms)")
    ax.set_ylabel("frames")
    ax.legend(fontsize=7)
    fig.tight_layout()
    out = _png(fig)
    plt.close(fig)
    return out


def thumbnails(overlay: str | Path, onsets: list[Onset]) -> dict[int, str]:
    """A JPEG (base64) of the overlay's frame at each onset's frame, by frame index (the first
    :data:`MAX_THUMBS` onsets)."""
    import cv2

    cap = cv2.VideoCapture(str(overlay))
    out: dict[int, str] = {}
    try:
        for o in onsets[:MAX_THUMBS]:
            if o.frame in out:
                continue
            cap.set(cv2.CAP_PROP_POS_FRAMES, o.frame)
            ok, frame = cap.read()
            if not ok:
                continue
            h, w = frame.shape[:2]
            small = cv2.resize(frame, (THUMB_WIDTH, max(1, round(h * THUMB_WIDTH / w))), interpolation=cv2.INTER_AREA)
            ok, jpg = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, 80])
            if ok:
                out[o.frame] = base64.b64encode(jpg.tobytes()).decode()
    finally:
        cap.release()
    return out


def _table(rows: list[list[Any]], head: list[str] | None = None) -> str:
    """A table; ``head`` None for one of names and values (no header row)."""
    cells = "".join(f"<th>{html.escape(h)}</th>" for h in head) if head else ""
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table>{f'<tr>{cells}</tr>' if cells else ''}{body}</table>"


UNITS = {"_m": "m", "_deg": "deg", "_s": "s", "_ms": "ms", "_px": "px"}


def plain(value: Any) -> str:
    """A value of the summary in words and units: ``height 1.50 m, pitch -2.88 deg`` for
    ``{"height_m": 1.5, "pitch_deg": -2.884}``, ``-`` for nothing, numbers rounded to what they are."""
    if value is None or value == {} or value == []:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 1e-3 or abs(value) >= 1e4 else f"{value:.2f}".rstrip("0").rstrip(".")
    if isinstance(value, dict):
        said = []
        for k, v in value.items():
            unit = next((u for suffix, u in UNITS.items() if str(k).endswith(suffix)), "")
            name = str(k)[: -len(next(s for s in UNITS if str(k).endswith(s)))] if unit else str(k)
            said.append(f"{name.replace('_', ' ')} {plain(v)}{' ' + unit if unit and not isinstance(v, dict) else ''}")
        return ", ".join(said)
    if isinstance(value, list | tuple):
        return ", ".join(plain(v) for v in value)
    return str(value)


def _converged(cal: dict[str, Any]) -> str:
    at = cal.get("converged_at")
    if at:
        return f"at frame {at['frame']}" + (f", {at['seconds']:g} s in" if at.get("seconds") is not None else "")
    if cal.get("source") in (None, "online"):
        return "no" if cal.get("source") == "online" else "-"
    return f"not calibrated online: the mounting is the {cal['source']}'s"


def page(drive: Drive, record: dict[str, Any], picture: str, thumbs: dict[int, str], title: str,
         histogram: str = "") -> str:
    """The HTML page: ``record`` is ``report.json``'s content, ``picture`` the timelines and ``histogram`` the
    frames' latency (base64 PNGs)."""
    e = html.escape
    ident, cal = record["identity"], record["calibration"]
    model = ident["model"]
    parts = [f"<h1>{e(title)}</h1>",
             "<h2>The run</h2>",
             _table([["source", e(str(ident.get("source")))],
                     ["model", e(f"{model.get('variant')}, graph {str(model.get('graph_sha256') or '')[:16]}, "
                                 f"config {model.get('config_digest')}, threshold {model.get('threshold')}")],
                     ["signed by", e(str(model.get("signer")) if model.get("authentic") else "NOT a trusted key")],
                     ["settings digest", e(str(ident.get("settings_digest")))],
                     ["machine", e(plain(ident.get("machine")))],
                     ["frames", f"{record['frames']} ({record['valid_frames']} with levels)"],
                     ["on the bus", e(_on_bus(record.get("on_bus") or {}))]]),
             "<h2>Calibration</h2>",
             _table([["camera from", e(plain(cal.get("source")))],
                     ["first guess", e(plain(cal.get("first_guess")))],
                     ["converged", e(_converged(cal))],
                     ["mounting", e(plain(cal.get("mounting")))],
                     ["hood", e(plain(cal.get("hood")))]]),
             "<h2>Timelines</h2>",
             f'<img alt="timelines" src="data:image/png;base64,{picture}" style="max-width:100%">',
             "<p>Per sector: the smoothed score (line) against the CAUTION and WARNING thresholds (dashed), the "
             "level (shading) and the distance to the nearest blind spot (dots, right axis); the system state and "
             "the frames with a fault (x); each stage's milliseconds per frame. The dotted line: calibration "
             "converged.</p>",
             "<h2>Level onsets</h2>"]
    rows = []
    for o in record["onsets"]:
        img = thumbs.get(o["frame"])
        pic = f'<img src="data:image/jpeg;base64,{img}" width="{THUMB_WIDTH}">' if img else ""
        dist = "" if o["distance_m"] is None else f"{o['distance_m']:.1f} m"
        rows.append([e(o["sector"]), e(o["level"]), f"{o['t']:.2f} s", o["frame"], dist, pic])
    parts.append(_table(rows, ["sector", "level", "time", "frame", "distance", "overlay"]) if rows
                 else "<p>No level was raised.</p>")
    lat = record["latency_ms"]
    cpu = record.get("cpu") or {}
    parts += ["<h2>Latency and CPU</h2>",
              _table([[e(s), *(f"{v:.2f} ms" for v in p.values())] for s, p in lat.items()],
                     ["stage", "p50", "p95", "p99"])]
    if cpu.get("cpu_ms_per_frame") is not None:
        parts.append(f"<p>CPU: {cpu['cpu_ms_per_frame']:.1f} ms a frame (every thread of the process, from the 20th "
                     f"frame to the last), {plain(cpu.get('cores_busy'))} cores busy over those frames.</p>")
    if histogram:
        parts.append(f'<img alt="latency histogram" src="data:image/png;base64,{histogram}">')
    parts += _states_section(drive)
    parts += _bus_section(record.get("bus_check")) + _camera_section(record.get("camera") or [])
    if record["damaged_lines"]:
        parts += ["<h2>Damaged lines of the frame log</h2>",
                  _table([[d["line"], e(d["why"])] for d in record["damaged_lines"]], ["line", "why"])]
    style = ("body{font-family:sans-serif;max-width:1300px;margin:auto}table{border-collapse:collapse;margin:8px 0}"
             "td,th{border:1px solid #ccc;padding:3px 8px;font-size:13px;text-align:left}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>{e(title)}</title><style>{style}</style>"
            f"</head><body>{''.join(parts)}</body></html>\n")


def _bus_section(check: dict[str, Any] | None) -> list[str]:
    """The bus checked against the frame log, with the damaged frames counted (none without a CAN log)."""
    if check is None:
        return []
    e = html.escape
    verdict = "the bus carried every onset of the frame log, and no other" if check["agree"] \
        else "<b>the bus and the frame log DISAGREE</b>"
    parts = ["<h2>The bus against the frame log</h2>", f"<p>{verdict}.</p>",
             _table([[e(n), s["log"], s["bus"], e(", ".join(s["only_in_log"]) or "-"),
                      e(", ".join(s["only_on_bus"]) or "-")] for n, s in check["sectors"].items()],
                    ["sector", "onsets in the log", "on the bus", "only in the log", "only on the bus"])]
    if check.get("disagreements"):
        parts.append("<p>Each disagreement, with its time (the frame log's clock, or seconds into the CAN log), "
                     "the bus's states of the cycles around it and what explains it:</p>")
        parts.append(_table([[e(d["where"]), e(d["sector"]), e(d["level"]), f"{d['t_s']:.2f} s",
                              e(", ".join(f"{a['t_s']:.2f} s {a['state']}" for a in d["around"]) or "-"), e(d["why"])]
                             for d in check["disagreements"]],
                            ["where", "sector", "level", "at", "the bus around it", "why"]))
    parts += _cycles_part(check.get("cycles"))
    damaged = check.get("damaged_frames") or {}
    if damaged or check.get("unreadable"):
        parts.append("<p>Damaged frames on the bus, counted and never taken as onsets: "
                     + e(", ".join(f"{n} with a {k}" if k == "bad CRC" else f"{n}: {k}" for k, n in damaged.items())
                         or "none") + (f"; {e(check['unreadable'])}" if check.get("unreadable") else "")
                     + f" (of {check.get('hazard_frames', 0)} hazard frames).</p>")
    return parts


def _on_bus(on_bus: dict[str, Any]) -> str:
    """"OK 1.5 s; UNAVAILABLE 0.3 s (stall ... 0.2 s, ...)": the summary's time in each state and why ("-"
    without a summary)."""
    from bsn_edge.runtime.run_summary import states_said

    said = states_said(on_bus.get("states_s") or {}, on_bus.get("why_s") or {})
    return said + "; then UNAVAILABLE, the last word" if said else "-"


def _cycles_part(cycles: dict[str, Any] | None) -> list[str]:
    """The bus cycle by cycle against the frames whose levels each cycle carried."""
    e = html.escape
    if not cycles:
        return []
    if not cycles["numbered"]:
        return ["<p>This frame log does not number the bus's cycles (written before <code>bus_from</code>): "
                "the bus is compared by its onsets only.</p>"]
    parts = [f"<p>Cycle by cycle: {cycles['compared']} hazard frames compared with the frame each carried, "
             f"{cycles['agree']} agree, {cycles['disagree']} differ; {cycles['not_compared']} not compared "
             "(UNAVAILABLE, or no status to say the cycle had levels).</p>"]
    if cycles["disagreements"]:
        parts.append(_table([[d["cycle"], f"{d['t_s']:.2f} s", "-" if d["frame"] is None else d["frame"],
                              e(" ".join(d["bus"])), e(" ".join(d["log"])),
                              e("; ".join(f"#{a['cycle']} {a['t_s']:.2f} s {a['state'] or '?'} {' '.join(a['levels'])}"
                                          for a in d["around"])), e(d["why"])] for d in cycles["disagreements"]],
                            ["cycle", "at", "frame", "bus levels", "frame's levels", "the cycles around it", "why"]))
    return parts


def _states_section(drive: Drive) -> list[str]:
    """Every stretch the bus said other than OK, with why (from the frames of the stretch)."""
    rows = []
    for a, b, state in drive.states():
        if state == "OK":
            continue
        inside = [r for r in drive.records if a <= r.t <= b]
        said = list(dict.fromkeys(r.status.why for r in inside if r.status is not None and r.status.why))
        faults = sorted({r.fault.value for r in inside if r.fault is not None})
        blind = sorted({r.visibility.reason.name for r in inside if r.visibility is not None
                        and r.visibility.reason.name != "CLEAR"})
        if said:                  # the bus's own reasons, as the run decided them
            why = "; ".join(said) + (" (faults of frames: " + ", ".join(faults) + ")" if faults else "")
        elif blind:
            why = "the camera: " + ", ".join(blind)
        elif faults:
            why = "faults: " + ", ".join(faults)
        elif state == "CALIBRATING":
            why = "online calibration not yet converged (levels from an assumed camera)"
        elif state == "DEGRADED":
            why = "valid frames a second under health.fps_floor, or an output or a bus that failed"
        else:
            why = "no valid frame within health.deadline_s (a stall), or the run's start or end"
        rows.append([f"{a:.2f} s", f"{b:.2f} s", html.escape(state), html.escape(why)])
    if not rows:
        return []
    return ["<h2>When the bus did not say OK</h2>", _table(rows, ["from", "to", "state", "why"])]


def _camera_section(spans: list[dict[str, Any]]) -> list[str]:
    """When the camera-health check said the camera could not see (nothing when it never did)."""
    if not spans:
        return []
    e = html.escape
    return ["<h2>When the camera could not see</h2>",
            "<p>The camera-health check's reason on the bus (<code>BSN_Status.Camera_Reason</code>): a reason "
            "of the whole picture reads UNAVAILABLE, PARTIAL reads DEGRADED for the sectors it names.</p>",
            _table([[f"{c['from_t']:.2f} s", f"{c['to_t']:.2f} s", e(c["reason"]), e(", ".join(c["unseen"]) or "-")]
                    for c in spans], ["from", "to", "reason", "sectors it cannot see"])]
