"""Reading numbers from user files: a missing or non-numeric field is an error that names it.

Every ``from_dict`` that reads a file a user can edit (camera files, model cards, configs) takes its
numbers through :func:`number`, so no field silently falls back to a default.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any


def number(d: Mapping[str, Any], key: str, where: str, kind: type = float) -> float | int:
    """``d[key]`` as a finite ``kind`` (float or int); ``ValueError`` naming ``key`` and ``where``
    when it is missing, not a number (booleans and numeric strings included), or not finite."""
    if not isinstance(d, Mapping):
        raise ValueError(f"{where}: expected a JSON object, got {type(d).__name__}")
    if key not in d or d[key] is None:
        raise ValueError(f"{where}: field {key!r} is missing")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError(f"{where}: field {key!r} must be a number, got {v!r:.40}")
    if not math.isfinite(v):
        raise ValueError(f"{where}: field {key!r} must be finite, got {v!r}")
    if kind is int:
        if float(v) != int(v):
            raise ValueError(f"{where}: field {key!r} must be a whole number, got {v!r}")
        return int(v)
    return float(v)
