"""Reading user files: a file that is not what it should be, or a missing or non-numeric field, is an
error that names the path or the field.

Every reader of a JSON file a user can edit (camera files, sequence metadata, training runs) opens it
through :func:`read_json_object`, and every ``from_dict`` takes its numbers through :func:`number`, so
no field silently falls back to a default.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from bsn_edge.user_file import read_user_file

MAX_MAGNITUDE = 10 ** 15      # a whole number past this in a camera file or card is damage, not a value


def read_json_object(path: str | os.PathLike, what: str = "", error: type[Exception] = ValueError) -> dict[str, Any]:
    """The JSON object in ``path``; ``error`` naming the path (and ``what`` it should be, e.g. "not a
    camera file") when it is not JSON, not text or not an object. A missing file is the caller's to
    name (``FileNotFoundError`` from the read otherwise)."""
    p = Path(path)
    lead = f"{p}: {what} (" if what else f"{p}: "
    tail = ")" if what else ""
    try:
        d = json.loads(read_user_file(p, "JSON").decode("utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
        raise error(f"{lead}not valid JSON: {e}{tail}") from None
    if not isinstance(d, dict):
        raise error(f"{lead}expected a JSON object, got {type(d).__name__}{tail}")
    return d


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
    if isinstance(v, int) and abs(v) > MAX_MAGNITUDE:
        # a 400-digit number: no camera's field, and float() of it would overflow
        raise ValueError(f"{where}: field {key!r} must be a finite number, got one of {len(str(v))} digits")
    if not math.isfinite(v):
        raise ValueError(f"{where}: field {key!r} must be finite, got {v!r}")
    if kind is int:
        if float(v) != int(v):
            raise ValueError(f"{where}: field {key!r} must be a whole number, got {v!r}")
        return int(v)
    return float(v)
