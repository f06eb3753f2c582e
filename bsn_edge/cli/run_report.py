"""The end of a ``bsn-run``: the summary written and said in a few lines, what failed warned of, the exit code;
and the summary of a run that ended before its first frame."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

from bsn_edge.cli.stop_signal import exit_code

if TYPE_CHECKING:
    from bsn_edge.alerts.senders import Sender
    from bsn_edge.runtime.camera_state import CameraState

PROG = "bsn-run"


def write_summary(path: str, record: dict[str, Any]) -> str:
    """``record`` written to ``path`` whole or not at all (a pipe written into); the error to say, or ""."""
    from bsn_edge.sequence.images import atomic_write_bytes

    try:
        atomic_write_bytes(path, (json.dumps(record, indent=1) + "\n").encode())
    except OSError as e:
        return f"cannot write the summary {path}: {e}"
    return ""


def early_summary(path: str | None, **record: Any) -> bool:
    """The summary of a run that ended in start-up (refused, or stopped by a signal): no frame, what ended it;
    whether it could be written (said on stderr when not). Nothing asked for is nothing to fail."""
    error = write_summary(path, {"frames": 0, "valid_frames": 0, **record, "phase": "start-up"}) if path else ""
    if error:
        print(f"{PROG}: error: {error}", file=sys.stderr)
    return not error


def _cpu_said(summary: dict[str, Any]) -> str:
    """", CPU 14.2 ms a frame (21 % of 2 cores)" from the summary's ``cpu`` ("" for a run too short)."""
    import os

    cpu = summary.get("cpu") or {}
    if cpu.get("cpu_ms_per_frame") is None:
        return ""
    cores = os.cpu_count() or 1
    busy = cpu.get("cores_busy")
    return f", CPU {cpu['cpu_ms_per_frame']:.1f} ms a frame" + (
        f" ({100 * busy / cores:.0f} % of {cores} cores)" if busy is not None else "")


def _faults_line(summary: dict[str, Any]) -> str:
    """"  faults: ...; on the bus: OK 1.5 s, ... (why); then UNAVAILABLE, the last word"."""
    from bsn_edge.alerts.health import Fault

    # an unsigned model is said on its own line, not as a fault
    faults = {k: v for k, v in summary["faults"].items() if v and k != Fault.UNSIGNED_MODEL}
    seen = (summary.get("visibility") or {}).get("seconds") or {}
    said = [f"{k} {v}" for k, v in faults.items()]
    said += [f"camera {reason} {secs:.1f} s" for reason, secs in seen.items()]
    if summary.get("stall_cycles"):
        said.append(f"stall cycles {summary['stall_cycles']} (the loop held up past health.deadline_s: UNAVAILABLE)")
    said += [f"bus down: {name}" for name in summary.get("senders_down") or ()]
    from bsn_edge.runtime.run_summary import states_said

    on_bus = states_said(summary.get("states_s") or {}, summary.get("why_s") or {})
    return ("  faults: " + (", ".join(said) if said else "none") + (f"; on the bus: {on_bus}" if on_bus else "")
            + ("; then UNAVAILABLE, the last word" if on_bus else ""))


def human_summary(summary: dict[str, Any], args: argparse.Namespace, camera: CameraState) -> str:
    """The end of a run in a few lines (the whole record goes to ``--summary``)."""
    lines = [f"{PROG}: {summary['frames']} frames ({summary['valid_frames']} valid) in {summary['seconds']:.1f} s: "
             f"{summary['fps']:.1f} frames/s, latency p50 {summary['p50_ms']:.1f} ms, p99 {summary['p99_ms']:.1f} ms"
             + (f", {summary['dropped']} dropped" if summary["dropped"] else "")
             + _cpu_said(summary)]
    if getattr(args, "profile", None):
        lines.append("  per stage, ms a frame (mean): " + ", ".join(
            f"{k} {v:.2f}" for k, v in summary["stage_ms"].items()))
    lines.append(_faults_line(summary))
    model = summary["model"]
    lines.append(f"  model: signed by key {model['signer']}" if model["authentic"]
                 else f"  model: UNSIGNED ({model['trust_note']}; run by --allow-unsigned)")
    m = summary["camera"]["mounting"]
    if summary["camera"]["cameras"]["cameras"] != "one camera":
        lines.append(f"  camera: {camera.progress()}")
    elif camera.calibrating:
        lines.append(f"  camera: still {camera.progress()}; online calibration needs a few seconds of straight "
                     "forward driving, longer with turns, stops or little texture (or run bsn-calibrate --mount once "
                     "and pass --calib)")
        lines.append(f"  levels computed meanwhile with: {camera.assumed()}")
    elif m is not None:
        report = summary["camera"]["calibration"]
        source = report.get("source", "camera file")
        at = report.get("converged_at")
        if at:
            source += f", converged at frame {at['frame']}" + (f", {at['seconds']:g} s in" if at["seconds"] else "")
        lines.append(f"  camera: height {m['height_m']:.2f} m, pitch {m['pitch_deg']:+.2f}, yaw {m['yaw_deg']:+.2f}, "
                     f"roll {m['roll_deg']:+.2f} deg ({source})")
        if at and at["frame"] > 1 and camera.assumed():   # the levels sent before it were an assumed camera's
            lines.append(f"  levels before frame {at['frame']} computed with an assumed camera: {camera.assumed()}")
    guess = summary["camera"].get("first_guess")
    if guess:
        lines.append("  first guess: " + (f"pitch {guess['pitch_deg']:+.2f} yaw {guess['yaw_deg']:+.2f} deg from the "
                                          f"road's vanishing point ({guess['frames_found']} frames agree)"
                                          if guess["used"] else f"the model camera's mounting (vanishing point "
                                          f"{guess['state']})"))
    lines.append(f"  hood: {camera.hood.describe() if camera.hood is not None else camera.hood_progress()}")
    outputs = [(name, getattr(args, key)) for name, key in (("overlay", "overlay"), ("frame log", "log"),
                                                               ("CAN log", "can_log"), ("maps", "save_maps"),
                                                               ("camera file", "save_calib"), ("summary", "summary"))
               if getattr(args, key)]
    if outputs:
        lines.append("  outputs: " + ", ".join(f"{name} {path}" for name, path in outputs))
    if getattr(args, "profile", None):
        lines.append(f"  the profile's page: bsn-report {args.log} --summary {args.summary} "
                     f"--out {args.profile}/report (needs the [full] or [report] install)")
    return "\n".join(lines)



def report(summary: dict[str, Any], args: argparse.Namespace, camera: CameraState, senders: list[Sender],
            signame: str | None) -> int:
    """The summary written and printed, warnings for what failed; the exit code."""
    summary_error = write_summary(args.summary, summary) if args.summary else ""
    print(human_summary(summary, args, camera))
    if summary_error:
        print(f"{PROG}: error: {summary_error}", file=sys.stderr)
    for name, sink in summary["sinks"].items():
        if sink["failure"]:
            f = sink["failure"]
            where = "when it was opened" if f["frame"] is None else f"at frame {f['frame']}"
            print(f"{PROG}: warning: the {name} output failed {where} ({f['error']}); the alerts went on, DEGRADED",
                  file=sys.stderr)
        if sink.get("dropped"):
            print(f"{PROG}: note: {sink['dropped']} frames left out of the {name} output, which fell behind the "
                  "camera (the alerts had them)", file=sys.stderr)
    for s in senders:
        if s.stats.errors:
            print(f"{PROG}: warning: {s.name} failed {s.stats.errors} times ({s.stats.last_error})", file=sys.stderr)
        if s.stats.log_errors:
            print(f"{PROG}: warning: the CAN log failed ({s.stats.log_error}); the bus went on, DEGRADED",
                  file=sys.stderr)
    if summary.get("senders_down"):
        print(f"{PROG}: error: {', '.join(summary['senders_down'])} could not send at the end of the run "
              "(DEGRADED while it was down)", file=sys.stderr)
        return 1
    if summary["source_failure"]:
        print(f"{PROG}: error: the source failed: {summary['source_failure']}", file=sys.stderr)
        return 1
    if not summary["frames"] and signame is None and not summary.get("stopped"):
        print(f"{PROG}: error: the source delivered no frame (an empty or unreadable video, an empty folder): "
              "nothing was seen, UNAVAILABLE was the bus's only word", file=sys.stderr)
        return 1
    if summary["frames"] and not summary["valid_frames"]:
        print(f"{PROG}: error: none of the {summary['frames']} frames gave a valid inference (see the faults)",
              file=sys.stderr)
        return 1
    if signame not in (None, "SIGTERM"):
        print(f"{PROG}: stopped by {signame}", file=sys.stderr)
        return exit_code(signame)
    return 1 if summary_error else 0
