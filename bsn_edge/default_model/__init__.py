"""The shipped default model: int8, signed with the project's release key, with its resolved card beside it.

It travels inside the package, so an installed wheel runs it with no checkout (``bsn-run`` without
``--model``, ``bsn-demo`` from any folder); ``models/default`` in a checkout is the run it was exported from.
"""

from __future__ import annotations

from pathlib import Path

DEFAULT_MODEL = Path(__file__).resolve().with_name("bsn_shared_light_int8.onnx")
DEFAULT_CARD = DEFAULT_MODEL.with_suffix(".json")
