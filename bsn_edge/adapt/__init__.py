"""``bsn-adapt``: a trained run adapted to a user's camera and roads from unlabelled video."""

from bsn_edge.adapt.config import AdaptConfig
from bsn_edge.adapt.pipeline import AdaptError, adapt

__all__ = ["AdaptConfig", "AdaptError", "adapt"]
