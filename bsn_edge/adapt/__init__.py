"""``bsn-adapt``: a trained run adapted to a user's camera and roads from unlabelled video."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bsn_edge.adapt.config import AdaptConfig

if TYPE_CHECKING:
    from bsn_edge.adapt.pipeline import AdaptError, adapt

__all__ = ["AdaptConfig", "AdaptError", "adapt"]


def __getattr__(name: str) -> Any:
    # the pipeline (torch) when it is asked for: the settings alone (bsn-adapt --help) need none of it
    if name in ("AdaptError", "adapt"):
        from bsn_edge.adapt import pipeline

        return getattr(pipeline, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
