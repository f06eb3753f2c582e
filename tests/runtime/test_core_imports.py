"""The car-side core stays small: bsn-run, bsn-listen and bsn-calibrate load no training tools (the
static check of every torch-free package is in tests/test_layers.py)."""

import json
import subprocess
import sys

import pytest

from bsn_edge.cli.common import CHECKOUT

HEAVY = ("torch", "onnx", "onnxruntime.quantization", "matplotlib")


@pytest.mark.parametrize("module", ["bsn_edge.cli.run", "bsn_edge.cli.listen", "bsn_edge.cli.calibrate"])
def test_importing_a_car_command_loads_no_training_tool(module):
    code = (f"import sys, json, {module}; "
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=CHECKOUT)
    assert json.loads(out.stdout) == [], f"{module} imports {out.stdout.strip()}"
