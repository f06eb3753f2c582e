"""The packages are layers: each imports only from layers below it, so no import cycle can come back.

Lowest first. A module imports from its own package or from a lower layer, never from its own layer's
other packages or from above (imports inside functions count too).
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# where the packages of bsn_edge live in the checkout (see pyproject's package-dir)
FOLDERS = {"bsn_edge": ROOT / "bsn_edge", "export": ROOT / "export", "alerts": ROOT / "alerts",
           "calibration": ROOT / "calibration"}
LAYERS = [
    ("fields",),
    ("camera",),
    ("mounting",),
    ("semantics", "sequence", "tracks", "metrics", "card", "model_frame"),
    ("calibration",),
    ("synth", "alerts"),
    ("runtime",),
    ("labels",),
    ("models",),
    ("data",),
    ("train",),
    ("evaluate",),
    ("export",),
    ("adapt",),
    ("cli",),
]
LEVEL = {pkg: i for i, layer in enumerate(LAYERS) for pkg in layer}


def unit(module: str) -> str | None:
    """``bsn_edge.labels.vo`` -> ``labels``; the top-level ``bsn_edge`` package itself -> None."""
    parts = module.split(".")
    return parts[1] if parts[0] == "bsn_edge" and len(parts) > 1 else None


def modules():
    for name, folder in FOLDERS.items():
        for f in sorted(folder.rglob("*.py")):
            rel = f.relative_to(folder)
            if name == "bsn_edge":
                pkg = rel.parts[0].removesuffix(".py") if rel.parts[0] != "__init__.py" else None
            else:
                pkg = name
            yield f, pkg


def test_every_package_has_a_layer():
    pkgs = {pkg for _, pkg in modules() if pkg is not None}
    assert pkgs == set(LEVEL), f"place these in LAYERS: {sorted(pkgs - set(LEVEL))}; gone: {sorted(set(LEVEL) - pkgs)}"


def test_no_package_imports_from_its_own_layer_or_above():
    bad = []
    for f, pkg in modules():
        if pkg is None:
            continue
        for node in ast.walk(ast.parse(f.read_text())):
            names = [node.module] if isinstance(node, ast.ImportFrom) and node.module else \
                [a.name for a in node.names] if isinstance(node, ast.Import) else []
            for name in names:
                target = unit(name)
                if target is None or target == pkg:
                    continue
                if LEVEL[target] >= LEVEL[pkg]:
                    bad.append(f"{f.relative_to(ROOT)}:{node.lineno} ({pkg}) imports {name} ({target})")
    assert not bad, "\n".join(bad)
