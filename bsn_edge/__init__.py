"""bsn-edge: where on the road a forward dashcam cannot see.

Subpackages follow the data flow: ``synth`` (a synthetic driving world),
``sequence`` (the on-disk clip format every stage shares), then labels,
models, export, runtime and alerts.
"""

from __future__ import annotations


def __getattr__(name: str) -> str:
    # read when asked, not at import: every command imports this package first, and bsn-run's signal
    # handlers wait for it (importlib.metadata alone took 21 ms of a 40 ms start)
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("bsn-edge")      # pyproject.toml's, as installed
        except PackageNotFoundError:        # imported from a source tree that was never installed
            return "0+unknown"
    raise AttributeError(f"module 'bsn_edge' has no attribute {name!r}")
