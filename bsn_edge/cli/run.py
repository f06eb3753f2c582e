"""``bsn-run``: dashcam video in, left / centre / right hazard levels out.

This module imports only the standard library at its top: ``main`` watches the terminating signals
(TERM, INT, HUP, QUIT) before anything else (the runtime's modules take a while to import), so a signal
at any moment of start-up ends the run cleanly.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING

from bsn_edge.cli.common import fail
from bsn_edge.cli.console import console_streams, lost
from bsn_edge.cli.outputs import (
    OutputKind,
    OutputsRefusedError,
    check_distinct,
    check_not_inputs,
    check_outputs,
    judge_output,
    prepare_output,
)
from bsn_edge.cli.run_args import CAN_LOG_EXTS, OVERLAY_EXTS, build_parser
from bsn_edge.cli.run_report import PROG, early_summary, report
from bsn_edge.cli.stop_signal import StopOnSignal, exit_code

if TYPE_CHECKING:
    from bsn_edge.alerts.bus_config import BusConfig
    from bsn_edge.alerts.senders import Sender
    from bsn_edge.runtime.settings import RuntimeConfig


def runtime_settings(args: argparse.Namespace) -> RuntimeConfig:
    """The runtime's settings: the defaults, ``--config``, ``--set``, then the shorthand flags."""
    from bsn_edge.runtime.config_file import load_runtime_config

    pairs = (("runtime.cycle_s", args.cycle), ("runtime.in_flight", args.in_flight),
             ("runtime.threads", args.threads), ("source.stall_s", args.stall))
    shorthand = [f"{k}={v}" for k, v in pairs if v is not None] + (["runtime.overlap=false"] if args.in_turn else []) \
        + (["runtime.spin=true"] if args.spin else ["runtime.spin=false"] if args.no_spin else [])
    return load_runtime_config(args.config, [*args.overrides, *shorthand])


def _output_files(args: argparse.Namespace) -> list[tuple[OutputKind, str | None]]:
    """The files a run writes, with what each writer knows, the CAN log first (``--save-maps`` is a folder:
    ``MapWriter``'s)."""
    return [(OutputKind("--can-log", CAN_LOG_EXTS, "CAN log (candump, ASC or BLF, which bsn-listen reads back)"),
             args.can_log),
            (OutputKind("--overlay", OVERLAY_EXTS, "video"), args.overlay),
            (OutputKind("--log", (".jsonl",), "frame log"), args.log),
            (OutputKind("--summary", (".json",), "summary"), args.summary),
            (OutputKind("--save-calib", (".json",), "camera"), args.save_calib)]


def make_senders(args: argparse.Namespace, bus: BusConfig | None = None,
                 sectors: tuple[str, ...] | None = None) -> list[Sender]:
    """The configured senders: the buses the flags name, else the vehicle file's (``bus``, which also
    gives baud rate and timeouts), encoding for the layout's ``sectors`` (the default layout's when None, as
    before the vehicle file is read); ``ValueError`` names the bad option (a sender already opened has said
    UNAVAILABLE and is closed again)."""
    from bsn_edge.alerts.bus_outputs import bus_outputs, open_senders
    from bsn_edge.alerts.dbc import bus_layout

    outputs = bus_outputs(args.can, args.serial, args.can_log, bus, tuple(getattr(args, "output", ())))
    return open_senders(outputs, bus, layout=bus_layout(sectors))


def _inputs(args: argparse.Namespace) -> list[tuple[str, str | None]]:
    """The files a run reads, by flag."""
    return [("--source", args.source), ("--calib", args.calib), ("--model", args.model), ("--config", args.config),
            *(("--trust", t) for t in args.trust)]


def _refuse_outputs(args: argparse.Namespace, message: str, writable: bool = False) -> int:
    """Outputs refused. A vehicle bus or serial link asked for hears UNAVAILABLE. ``writable``: the refusal is
    not the CAN log's or the summary's own doing (a read-only folder, a file where another output's folder
    should be, an output naming an input): each of the two that can itself be written gets UNAVAILABLE and
    the reason. Otherwise (a file that exists without --force, a suffix the writer does not know) nothing is
    written: a command line to mend, not a run, and the next try is not refused for a file this one left."""
    usable = {kind.flag: path for kind, path in _output_files(args)
              if writable and path and kind.flag in ("--can-log", "--summary") and _can_write(kind, path, args)}
    try:
        senders = make_senders(argparse.Namespace(**{**vars(args), "can_log": usable.get("--can-log")}))
    except ValueError:
        senders = []
    return refuse(senders, message, usable.get("--summary"))


def _can_write(kind: OutputKind, path: str, args: argparse.Namespace) -> bool:
    """Whether this one output could be written: not there already (unless --force), no input and no other
    output of the run, on a disk that takes it."""
    if judge_output(kind, path, force=args.force) is not None:
        return False
    others = [(k, p) for k, p in _output_files(args) if p and k.flag != kind.flag]
    try:
        check_not_inputs([(kind.flag, path)], _inputs(args))
        for other in others:
            check_distinct([(kind, path), other])
        prepare_output(kind, path)
    except (ValueError, OSError):
        return False
    return True


def refuse(senders: list[Sender], message: str, summary: str | None = None) -> int:
    """The runtime cannot start: say UNAVAILABLE on every bus first, then the reason, in the summary too
    when one is asked for (``summary``: its path, already checked as an output)."""
    from bsn_edge.alerts.bus_outputs import last_word

    last_word(senders)
    early_summary(summary, refused=message)
    return fail(PROG, message + (" (UNAVAILABLE sent)" if senders else ""))


def main(argv: list[str] | None = None) -> int:
    # signals first: from here on SIGINT and SIGTERM end the run cleanly, during start-up included; once
    # the outputs are open, every way out ends with UNAVAILABLE on the bus
    with StopOnSignal(keep=argv is None) as stopper, console_streams(keep=argv is None) as console:
        if "--print-dbc" in (sys.argv[1:] if argv is None else argv):
            return print_dbc(argv)
        args = build_parser().parse_args(argv)
        args.console = console
        if args.profile:
            _profiled(args)
        return _run(args, stopper)


def print_dbc(argv: list[str] | None) -> int:
    """``--print-dbc``: the DBC of the layout the settings (``--config``, ``--set``) declare, on standard output
    (no source needed: only the settings are read)."""
    p = argparse.ArgumentParser(prog=PROG, add_help=False)
    p.add_argument("--config")
    p.add_argument("--set", dest="overrides", action="append", default=[])
    args, _ = p.parse_known_args(argv)
    from bsn_edge.alerts.dbc import bus_layout
    from bsn_edge.runtime.config_file import load_runtime_config

    try:
        cfg = load_runtime_config(args.config, args.overrides)
    except (ValueError, OSError) as e:
        return fail(PROG, str(e))
    sys.stdout.write(bus_layout(cfg.sectors.names).text())
    return 0


PROFILE_FRAMES = 300


def _profiled(args: argparse.Namespace) -> None:
    """``--profile DIR``: the frame log and the summary into DIR (unless named), the file paced, 300 frames."""
    from pathlib import Path

    args.log = args.log or str(Path(args.profile) / "frames.jsonl")
    args.summary = args.summary or str(Path(args.profile) / "summary.json")
    args.pace = True
    args.max_frames = args.max_frames if args.max_frames is not None else PROFILE_FRAMES


def _wrong_numbers(args: argparse.Namespace) -> str | None:
    """What is wrong with the command line's numbers (None: nothing)."""
    if args.max_frames is not None and args.max_frames < 1:
        return f"--max-frames must be >= 1, got {args.max_frames}"
    if args.stall is not None and not (args.stall > 0 and math.isfinite(args.stall)):
        return f"--stall must be a positive number of seconds, got {args.stall:g}"
    return None


def _stopped_early(args: argparse.Namespace, stopper: StopOnSignal, senders: list[Sender] | None = None) -> int:
    """A signal before the first frame: UNAVAILABLE on every bus asked for (opened now if need be), the
    summary written, the signal's exit code (1 when the summary could not be written)."""
    from bsn_edge.alerts.bus_outputs import last_word

    if senders is None:
        try:
            senders = make_senders(args)
        except ValueError:
            senders = []
    last_word(senders)
    written = early_summary(args.summary, stopped=True, signal=stopper.signal)
    print(f"{PROG}: stopped by {stopper.signal} during start-up" + (" (UNAVAILABLE sent)" if senders else ""),
          file=sys.stderr)
    code = exit_code(stopper.signal)
    return 1 if not written and code == 0 else code


def _judge_outputs(args: argparse.Namespace) -> int | None:
    """Every output judged before any is written: None when all can be, else the refusal's exit code."""
    try:
        check_not_inputs([(k.flag, path) for k, path in _output_files(args)] + [("--save-maps", args.save_maps)],
                         _inputs(args))
        check_distinct(_output_files(args))
    except (ValueError, OSError) as e:                # the summary and the CAN log, where they are free, say so
        return _refuse_outputs(args, str(e), writable=True)
    try:
        check_outputs(_output_files(args), args.force)
    except OutputsRefusedError as e:                  # a command line to mend: a file there, a wrong suffix
        return _refuse_outputs(args, str(e))
    except (ValueError, OSError) as e:                # the disk's: a folder that cannot be made or written
        return _refuse_outputs(args, str(e), writable=True)
    return None


def _run(args: argparse.Namespace, stopper: StopOnSignal) -> int:
    if stopper.event.is_set():
        return _stopped_early(args, stopper)
    from bsn_edge.progress import progress_bar
    from bsn_edge.runtime import run
    if stopper.event.is_set():          # a signal while the runtime loaded
        return _stopped_early(args, stopper)
    if (refused := _judge_outputs(args)) is not None:
        return refused
    configured = _configured(args)
    if isinstance(configured, int):
        return configured
    cfg, senders = configured
    if (wrong := _wrong_numbers(args)) is not None:
        return refuse(senders, wrong, args.summary)
    try:                                              # from here a refusal is UNAVAILABLE on the bus and,
        # the outputs being free, said in the summary
        engine, camera, source, maps = _start(args, cfg)
    except (FileNotFoundError, ValueError, OSError) as e:
        if stopper.event.is_set():     # the first signal decides, even over a refusal it came during
            return _stopped_early(args, stopper, senders)
        return refuse(senders, str(e), args.summary)
    if stopper.event.is_set():
        source.close()
        return _stopped_early(args, stopper, senders)
    stopper.watch(source)
    try:
        total = args.max_frames or getattr(source, "total", None)
        with progress_bar(total=total, unit="frame", desc="bsn-run", file=sys.stderr) as bar:
            shown = [""]

            def tick(n: int) -> None:
                bar.update(n)
                # every 25 frames while calibrating, and once more when it converges: never a stale line
                if bar.n % 25 == 0 or (shown[0].startswith("calibrating") and not camera.calibrating):
                    text = camera.progress()
                    if text != shown[0]:
                        bar.set_postfix_str(text, refresh=False)
                        shown[0] = text

            summary = run(engine, source, senders, cfg, overlay=args.overlay, log=args.log,
                          max_frames=args.max_frames, progress=tick, camera=camera, save_maps=maps,
                          stop=stopper.event)
    except OSError as e:            # an output that could not be opened: the bus has had UNAVAILABLE
        return fail(PROG, f"{e} (UNAVAILABLE sent)" if senders else str(e))
    except Exception as e:          # a fault of the runtime itself: the bus has had UNAVAILABLE
        return fail(PROG, f"the runtime stopped on {type(e).__name__}: {e}"
                          + (" (UNAVAILABLE sent)" if senders else ""), 1)
    finally:
        source.close()
        for s in senders:
            s.close()
    from bsn_edge.runtime.config_file import digest, to_dict
    from bsn_edge.runtime.run_summary import machine
    summary.update(signal=stopper.signal, source=args.source, machine=machine(), settings=to_dict(cfg),
                   settings_digest=digest(cfg), console=lost(args.console))
    return report(summary, args, camera, senders, stopper.signal)


def _configured(args: argparse.Namespace) -> tuple[RuntimeConfig, list[Sender]] | int:
    """The settings (``--config``, ``--set``, the shorthands) and the senders the flags or the settings name;
    an exit code when either is refused (settings refused: UNAVAILABLE to the buses the flags name)."""
    try:
        cfg = runtime_settings(args)
    except (ValueError, OSError) as e:         # FileNotFoundError for a --config that is not there
        try:
            senders = make_senders(args)
        except ValueError as e2:
            return fail(PROG, f"{e}; {e2}")
        return refuse(senders, str(e), args.summary)
    try:
        return cfg, make_senders(args, cfg.bus, cfg.sectors.names)
    except ValueError as e:
        return fail(PROG, str(e))


def _start(args: argparse.Namespace, cfg: RuntimeConfig):
    """What the run needs before its first frame, built by :func:`~bsn_edge.runtime.build.build_run` from the
    command line: ``(engine, camera, source, maps)``; ``FileNotFoundError``, ``ValueError`` or ``OSError``
    names what is wrong."""
    from bsn_edge.runtime.build import RunRequest, build_run

    request = RunRequest(source=args.source, model=args.model, calib=args.calib, height=args.height,
                         save_calib=args.save_calib, save_maps=args.save_maps, force=args.force,
                         trust=tuple(args.trust), allow_unsigned=args.allow_unsigned, pace=args.pace)
    built = build_run(request, cfg, say=lambda s: print(f"{PROG}: {s}", file=sys.stderr))
    return built.engine, built.camera, built.source, built.maps


if __name__ == "__main__":
    raise SystemExit(main())
