"""The packages are layers: each imports only from layers below it, so no import cycle can come back.

Lowest first. A module imports from its own package or from a lower layer, never from its own layer's
other packages or from above: ``import bsn_edge.x``, ``from bsn_edge.x import y``, ``from bsn_edge
import x``, relative imports (``from ..x import y``, resolved against the module's own place) and
``importlib.import_module("bsn_edge.x")`` alike, at the top or inside functions; ``from X import Y`` is
read as both ``X`` and ``X.Y`` for every ``X`` (``from onnxruntime import quantization`` names the
quantization tools), and an ``import_module`` or ``__import__`` whose name is not written out is refused
(nothing could say what it loads). The rules are the package's own (:mod:`bsn_edge.layers`): which packages
are torch-free (``TORCH_FREE``) and what they must not load (``HEAVY``, which ``tests/runtime/test_core_imports.py``
checks at run time too): the car's side, which ``bsn-run``, ``bsn-listen`` and ``bsn-calibrate`` load. Those
commands (:data:`CAR_COMMANDS`), ``bsn_edge/__init__.py`` and every module of the package they import, followed
import by import at the top or inside functions, are held to :data:`HEAVY` too.
"""

import ast
import functools
from pathlib import Path

import pytest

from bsn_edge import layers
from bsn_edge.layers import CAR_COMMANDS, HEAVY, LEVEL, TORCH_FREE

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "bsn_edge"


@functools.lru_cache(maxsize=2048)
def _parsed(text: str) -> ast.Module:
    """A module's tree, parsed once per text (the mutation tests check many copies of one package)."""
    return ast.parse(text)


def unit(module: str) -> str | None:
    """``bsn_edge.labels.vo`` -> ``labels``; the top-level ``bsn_edge`` package itself -> None."""
    parts = module.split(".")
    return parts[1] if parts[0] == "bsn_edge" and len(parts) > 1 else None


def modules(root: Path = PACKAGE):
    """Every module of the package below ``root`` and the package (first folder or module) it is in."""
    for f in sorted(root.rglob("*.py")):
        rel = f.relative_to(root)
        yield f, rel.parts[0].removesuffix(".py") if rel.parts[0] != "__init__.py" else None


def imported(tree: ast.AST, here: str = "bsn_edge") -> list[tuple[int, str]]:
    """``(line, module)`` of every import in ``tree`` of the module ``here`` (dotted, for relative imports):
    ``from X import y`` names ``X`` and ``X.y``, a relative import is resolved, and a call of
    ``import_module`` or ``__import__`` names its module when written out, its own package when the name is one
    of its package's modules (``f"{__package__}.{name}"``: a module checked here like the others), else
    ``<dynamic>``."""
    out = []
    package = here.split(".")
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                # level 1 is the module's own package, each further level one above it
                up = package[:len(package) - node.level + 1] if node.level <= len(package) else []
                base = ".".join([*up, *([base] if base else [])])
            if base:
                out.append((node.lineno, base))
            out += [(node.lineno, f"{base}.{a.name}" if base else a.name) for a in node.names if a.name != "*"]
        elif isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name in ("import_module", "__import__"):
                literal = node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
                out.append((node.lineno, node.args[0].value if literal else here if _own(node) else "<dynamic>"))
    return out


def _own(call: ast.Call) -> bool:
    """Whether ``call``'s module is named as one of the caller's own package: ``f"{__package__}.{...}"``."""
    arg = call.args[0] if call.args else None
    return (isinstance(arg, ast.JoinedStr) and bool(arg.values) and isinstance(arg.values[0], ast.FormattedValue)
            and isinstance(arg.values[0].value, ast.Name) and arg.values[0].value.id == "__package__")


def dotted(f: Path, root: Path) -> str:
    """The package a module's relative imports start from: ``bsn_edge/labels/vo.py`` -> ``bsn_edge.labels``
    (a package's ``__init__`` is in its own package)."""
    rel = f.relative_to(root.parent).with_suffix("")
    return ".".join(rel.parts[:-1])


def upward_imports(root: Path = PACKAGE) -> list[str]:
    bad = []
    for f, pkg in modules(root):
        if pkg is None:
            continue
        for line, name in imported(_parsed(f.read_text()), dotted(f, root)):
            if name == "<dynamic>":
                bad.append(f"{f.relative_to(root.parent)}:{line} ({pkg}) imports a module named at run time")
                continue
            target = unit(name)
            if target is None or target == pkg:
                continue
            if target not in LEVEL or LEVEL[target] >= LEVEL[pkg]:
                bad.append(f"{f.relative_to(root.parent)}:{line} ({pkg}) imports {name} ({target})")
    return bad


def heavy_imports(root: Path = PACKAGE) -> list[str]:
    bad = []
    for f, pkg in modules(root):
        if pkg not in TORCH_FREE:
            continue
        for line, name in imported(_parsed(f.read_text()), dotted(f, root)):
            if any(name == h or name.startswith(h + ".") for h in HEAVY):
                bad.append(f"{f.relative_to(root.parent)}:{line} ({pkg}, torch-free) imports {name}")
    return bad


def module_files(name: str, root: Path) -> list[Path]:
    """The files importing the package's module ``name`` runs: each enclosing package's ``__init__`` and the
    module itself (none for a name that is not a module of the package, such as a function's)."""
    parts = name.split(".")
    if parts[0] != "bsn_edge":
        return []
    files = []
    for k in range(1, len(parts) + 1):
        base = root.joinpath(*parts[1:k])
        if (base / "__init__.py").is_file():
            files.append(base / "__init__.py")
        elif base.with_suffix(".py").is_file():
            files.append(base.with_suffix(".py"))
            break
        else:
            break
    return files


def car_side(root: Path = PACKAGE) -> dict[Path, str]:
    """Every module of the package the car's commands load, each with the first one that loads it."""
    seen: dict[Path, str] = {}
    todo = [(root / c, c) for c in CAR_COMMANDS] + [(root / "__init__.py", "bsn_edge/__init__.py")]
    while todo:
        f, via = todo.pop()
        if f in seen:
            continue
        seen[f] = via
        for _, name in imported(_parsed(f.read_text()), dotted(f, root)):
            todo += [(g, str(f.relative_to(root.parent))) for g in module_files(name, root) if g not in seen]
    return seen


def car_heavy_imports(root: Path = PACKAGE) -> list[str]:
    bad = []
    for f, via in car_side(root).items():
        for line, name in imported(_parsed(f.read_text()), dotted(f, root)):
            if any(name == h or name.startswith(h + ".") for h in HEAVY):
                bad.append(f"{f.relative_to(root.parent)}:{line} (loaded by {via}, the car's side) imports {name}")
    return bad


def test_every_package_has_a_layer():
    pkgs = {pkg for _, pkg in modules() if pkg is not None}
    assert pkgs == set(LEVEL), f"place these in LAYERS: {sorted(pkgs - set(LEVEL))}; gone: {sorted(set(LEVEL) - pkgs)}"
    assert set(TORCH_FREE) <= set(LEVEL)


def test_no_package_imports_from_its_own_layer_or_above():
    bad = upward_imports()
    assert not bad, "\n".join(bad)


def test_no_torch_free_package_names_a_training_tool():
    bad = heavy_imports()
    assert not bad, "\n".join(bad)


def test_nothing_the_car_commands_load_names_a_training_tool():
    side = car_side()
    assert PACKAGE / "cli" / "common.py" in side and PACKAGE / "runtime" / "loop.py" in side   # it follows imports
    bad = car_heavy_imports()
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize(("module", "line"), [
    ("alerts/state_machine.py", "from bsn_edge import runtime"),
    ("alerts/state_machine.py", "importlib.import_module('bsn_edge.runtime')"),
    ("camera.py", "from bsn_edge import mounting"),
    ("runtime/loop.py", "from bsn_edge.train import trainer"),
    ("calibration/camera_file.py", "import torch"),
    ("runtime/loop.py", "from ..train import trainer"),
    ("runtime/loop.py", "from .. import export"),
    ("runtime/loop.py", "from onnxruntime import quantization"),
    ("alerts/sectors.py", "importlib.import_module('bsn_edge.' + 'train')"),
    ("alerts/sectors.py", "importlib.import_module(f'{__name__}.train')"),
    ("alerts/sectors.py", "importlib.import_module(f'bsn_edge.{__package__}')"),
    ("cli/run.py", "import torch"),
    ("cli/listen.py", "import onnx"),
    ("cli/calibrate.py", "from onnxruntime import quantization"),
    ("cli/calibrate.py", "from bsn_edge.export import pipeline"),
    ("cli/outputs.py", "from bsn_edge.train import run"),
    ("cli/common.py", "import matplotlib.pyplot"),
    ("__init__.py", "import torch"),
])
def test_the_checks_catch_each_way_of_importing_upwards(tmp_path, module, line):
    """Each form, written into a copy of the package, is found (the package itself is clean: the tests above)."""
    import shutil
    copy = tmp_path / "bsn_edge"
    shutil.copytree(PACKAGE, copy, ignore=lambda d, names: [n for n in names if (not n.endswith(".py")
                                                              and not (Path(d) / n).is_dir()) or n == "__pycache__"])
    target = copy / module
    target.write_text(target.read_text() + f"\n\ndef _probe():\n    import importlib\n    {line}\n")
    assert upward_imports(copy) + heavy_imports(copy) + car_heavy_imports(copy), f"{line} in {module} was not caught"


def test_a_module_of_its_own_package_named_at_run_time_is_its_own_packages():
    """``import_module(f"{__package__}.{name}")`` (how the outputs are found) stays in the caller's package."""
    tree = _parsed("import importlib\nimportlib.import_module(f'{__package__}.udp_output')\n")
    assert imported(tree, "bsn_edge.alerts") == [(1, "importlib"), (2, "bsn_edge.alerts")]


def test_the_development_page_shows_the_packages_layers_as_they_are():
    """``docs/development.md``'s layer table is what ``python -m bsn_edge.layers`` prints from the rules above."""
    assert layers.main(["--check", str(ROOT / "docs" / "development.md")]) == 0
