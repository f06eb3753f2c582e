"""The ``bsn-run`` command: the terminating signals are held from its first instruction, before the runtime's
command module is imported (about a tenth of a second), so a service manager's stop at any moment of
start-up ends the run cleanly, with UNAVAILABLE on the bus and the summary, never by the default action."""

from bsn_edge.cli.stop_signal import hold_signals

hold_signals()

from bsn_edge.cli.run import main  # noqa: E402  (after the signals are held: the point of this module)

__all__ = ["main"]

if __name__ == "__main__":
    raise SystemExit(main())
