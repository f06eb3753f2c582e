"""Rooms stay small: no function of the package is longer than a screen."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "bsn_edge"
MAX_FUNCTION_LINES = 60


def test_no_function_of_the_package_is_over_60_lines():
    long = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, "split these functions:\n" + "\n".join(long)


def test_the_check_sees_a_long_function(tmp_path):
    """The walk finds a function nested in a class (the shape of most of the package's long ones)."""
    src = "class A:\n    def f(self):\n" + "        x = 1\n" * MAX_FUNCTION_LINES
    node = next(n for n in ast.walk(ast.parse(src)) if isinstance(n, ast.FunctionDef))
    assert node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
