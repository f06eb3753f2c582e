"""bsn-edge: where on the road a forward dashcam cannot see.

Subpackages follow the data flow: ``synth`` (a synthetic driving world),
``sequence`` (the on-disk clip format every stage shares), then labels,
models, export, runtime and alerts.
"""

__version__ = "0.1.0"
