"""bsn-edge: where on the road a forward dashcam cannot see.

Subpackages follow the data flow: ``synth`` (a synthetic driving world),
``sequence`` (the on-disk clip format every stage shares), then labels,
models, export, runtime and alerts.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bsn-edge")      # pyproject.toml's, as installed
except PackageNotFoundError:               # imported from a source tree that was never installed
    __version__ = "0+unknown"
