"""The car-side core stays small: bsn-run, bsn-listen and bsn-calibrate load no training tools."""

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from bsn_edge.cli.common import CHECKOUT

HEAVY = ("torch", "onnx", "onnxruntime.quantization", "matplotlib")
CORE_DIRS = ("bsn_edge/runtime", "alerts", "calibration")


@pytest.mark.parametrize("module", ["bsn_edge.cli.run", "bsn_edge.cli.listen", "bsn_edge.cli.calibrate"])
def test_importing_a_car_command_loads_no_training_tool(module):
    code = (f"import sys, json, {module}; "
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=CHECKOUT)
    assert json.loads(out.stdout) == [], f"{module} imports {out.stdout.strip()}"


def test_no_core_module_names_a_training_tool():
    """Also the imports that run only on some paths (inside functions)."""
    bad = []
    for d in CORE_DIRS:
        for path in sorted((CHECKOUT / d).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                    [node.module or ""] if isinstance(node, ast.ImportFrom) else []
                bad += [f"{Path(path).relative_to(CHECKOUT)}: {n}" for n in names
                        if any(n == h or n.startswith(h + ".") for h in HEAVY)
                        or n.startswith(("bsn_edge.export", "bsn_edge.train", "bsn_edge.models"))]
    assert not bad, bad
