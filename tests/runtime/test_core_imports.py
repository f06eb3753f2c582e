"""The car-side core stays small: every module of every torch-free package (bsn_edge.layers.TORCH_FREE, the
static check's own list), and the car's commands, load none of the training tools (HEAVY, the same list the
static check uses) when imported, all in one interpreter as bsn-run would."""

import json
import subprocess
import sys

from bsn_edge.cli.common import CHECKOUT
from bsn_edge.layers import HEAVY, TORCH_FREE
from tests.test_layers import PACKAGE, modules

CAR_COMMANDS = ("bsn_edge.cli.run", "bsn_edge.cli.listen", "bsn_edge.cli.calibrate")


def car_side_modules() -> list[str]:
    out = []
    for f, pkg in modules():
        if pkg in TORCH_FREE:
            rel = f.relative_to(PACKAGE.parent).with_suffix("")
            out.append(".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts))
    return sorted(out)


def test_every_car_side_module_and_command_loads_no_training_tool():
    names = [*car_side_modules(), *CAR_COMMANDS]
    assert len(names) > 60, "every module of the car's side"
    code = ("import importlib, json, sys\n"
            f"for n in {names!r}:\n    importlib.import_module(n)\n"
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=CHECKOUT)
    assert json.loads(out.stdout) == [], f"the car's side loads {out.stdout.strip()}"
