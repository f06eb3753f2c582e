"""The vehicle settings file's JSON Schema and reference page, both generated from the settings themselves
(``python -m bsn_edge.runtime.config_schema`` writes them and the docs' settings table; ``--check`` says which
is stale).

The types and ranges come from the settings' dataclasses (``config_toml.setting``), the defaults from
their defaults, and each key's description from its comment in the shipped file
(:data:`~bsn_edge.runtime.config_file.DEFAULTS_FILE`, a key's own comment or its table's). So the schema
(``configs/runtime.schema.json``, checked in) and the reference page (``docs/settings.md``) cannot drift
from what ``bsn-run`` accepts: tests hold both to this module, and the shipped file to the schema.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from bsn_edge.runtime.config_file import DEFAULTS_FILE, LOOP, NESTED, SCHEMA_FILE
from bsn_edge.runtime.settings import RuntimeConfig

__all__ = ["SCHEMA_FILE", "comments", "reference_page", "schema"]
DRAFT = "https://json-schema.org/draft/2020-12/schema"
TABLE_LINE = _TABLE = re.compile(r"^\[([\w.]+)\]\s*(?:#\s?(.*))?$")
# as the docs say them
KINDS = {"boolean": "true or false", "integer": "whole number", "string": "text", "array": "list of text"}
KEY_LINE = _KEY = re.compile(r"^(\w+)\s*=\s*[^#]*?(?:#\s?(.*))?$")


def comments(path: Path = DEFAULTS_FILE) -> dict[str, str]:
    """Each key's description in the settings file, by dotted key (``alerts.caution.on``), and each table's
    by its name: the comment on its line, with the comment lines that follow it alone."""
    out: dict[str, str] = {}
    table, last = "", ""
    for line in path.read_text().splitlines():
        text = line.strip()
        if m := _TABLE.match(text):
            table, last = m.group(1), m.group(1)
            out[last] = (m.group(2) or "").strip()
        elif m := _KEY.match(text):
            last = f"{table}.{m.group(1)}"
            out[last] = (m.group(2) or "").strip()
        elif text.startswith("#") and last and out.get(last):
            out[last] += " " + text.lstrip("#").strip()     # a comment carried on to the next line
        else:
            last = ""
    return out


def leaves(node: dict[str, Any] | None = None, name: str = "") -> Iterator[tuple[str, dict[str, Any]]]:
    """Every setting of the schema (``node``: a table of it, named ``name``) as ``(dotted key, its node)``, in
    the file's order: a table's own keys, then its nested tables."""
    if node is None:
        for table, sub in schema()["properties"].items():
            yield from leaves(sub, table)
        return
    props = node["properties"]
    yield from ((f"{name}.{k}", v) for k, v in props.items() if v["type"] != "object")
    for k, v in props.items():
        if v["type"] == "object":
            yield from leaves(v, f"{name}.{k}")


def cell_default(v: dict[str, Any]) -> str:
    """A setting's default as the docs' tables write it, from its schema node."""
    d = v["default"]
    if v["type"] == "array" and v["items"]["type"] == "object":          # the sector layout
        return ", ".join(f"{s['name']} to {s['to_deg']:g}" if "to_deg" in s else s["name"] for s in d)
    return str(d).lower() if v["type"] == "boolean" else f'"{d}"' if v["type"] == "string" \
        else "[" + ", ".join(f'"{x}"' for x in d) + "]" if v["type"] == "array" else f"{d:g}"


def cell_kind(v: dict[str, Any]) -> str:
    """A setting's kind in words, from its schema node."""
    if v["type"] == "array" and v["items"]["type"] == "object":
        return "list of tables (" + ", ".join(v["items"]["properties"]) + ")"
    return KINDS.get(v["type"], "number")


def cell_range(v: dict[str, Any]) -> str:
    """``0.01 to 1 s``: a setting's range and unit, from its schema node ("" for none)."""
    if "minimum" not in v:
        return ""
    lo, hi = (f"{x:g}" if abs(x) < 1e5 else f"{x:,.0f}".replace(",", "_") for x in (v["minimum"], v["maximum"]))
    return f"{lo} to {hi}" + (f" {v['unit']}" if v.get("unit") else "")


def _layout(value: tuple[Any, ...]) -> dict[str, Any]:
    """The sector layout's node: a list of tables, each a name and (but the last) the bearing it ends at."""
    from bsn_edge.alerts.sectors import EDGE_DEG, MAX_SECTORS, NAME

    item = {"type": "object", "additionalProperties": False, "required": ["name"],
            "properties": {"name": {"type": "string", "pattern": NAME.pattern},
                           "to_deg": {"type": "number", "exclusiveMinimum": -EDGE_DEG, "exclusiveMaximum": EDGE_DEG,
                                      "unit": "deg"}}}
    default = [{k: v for k, v in dataclasses.asdict(s).items() if v is not None} for s in value]
    return {"type": "array", "minItems": 1, "maxItems": MAX_SECTORS, "items": item, "default": default}


def _leaf(f: dataclasses.Field, value: Any, description: str) -> dict[str, Any]:
    if isinstance(value, tuple) and value and dataclasses.is_dataclass(value[0]):     # sectors.layout
        return {**_layout(value), "description": description} if description else _layout(value)
    if isinstance(value, tuple):           # a list of names (bus.outputs)
        listed: dict[str, Any] = {"type": "array", "items": {"type": "string"}, "default": list(value)}
        return {**listed, "description": description} if description else listed
    kind = "boolean" if isinstance(value, bool) else "integer" if isinstance(value, int) \
        else "string" if isinstance(value, str) else "number"
    out: dict[str, Any] = {"type": kind, "default": value}
    if "range" in f.metadata:
        out["minimum"], out["maximum"] = f.metadata["range"]
        if f.metadata.get("unit"):
            out["unit"] = f.metadata["unit"]
    if description:
        out["description"] = description
    return out


def _table(instance: Any, name: str, said: dict[str, str]) -> dict[str, Any]:
    props: dict[str, Any] = {}
    for f in dataclasses.fields(instance):
        value = getattr(instance, f.name)
        if name == LOOP and f.name in NESTED:
            continue                       # a table of its own
        dotted = f"{name}.{f.name}"
        if dataclasses.is_dataclass(value):
            props[f.name] = _table(value, dotted, said)
        else:
            props[f.name] = _leaf(f, value, said.get(dotted) or said.get(name, ""))
    out: dict[str, Any] = {"type": "object", "additionalProperties": False, "properties": props}
    if said.get(name):
        out["description"] = said[name]
    return out


def schema() -> dict[str, Any]:
    """The JSON Schema of a vehicle settings file (read as TOML, it is a JSON object)."""
    said = comments()
    cfg = RuntimeConfig()
    tables = {LOOP: _table(cfg, LOOP, said), **{n: _table(getattr(cfg, n), n, said) for n in NESTED}}
    return {"$schema": DRAFT, "$id": "https://bsn-edge/runtime.schema.json",
            "title": "bsn-run vehicle settings",
            "description": "Every runtime setting of bsn-run, as its settings file (TOML) holds them; every key is "
                           "optional, a missing one keeps its default. The model's decision threshold is not "
                           "here: it is part of the signed model card, chosen with the model.",
            "type": "object", "additionalProperties": False, "properties": tables}


def reference_page() -> str:
    """``docs/settings.md``: every setting with its default, kind, range and description, from :func:`schema`."""
    lines = ["# Vehicle settings reference", "",
             "Generated from the settings themselves (`bsn_edge/runtime/config_schema.py`); a test holds this page, "
             "`configs/runtime.schema.json` and the shipped `configs/runtime.toml` to them. `bsn-run --print-config` "
             "prints the file with every key at its default; `bsn-run --print-schema` the JSON Schema. A key "
             "`bsn-run` does not have is refused with the nearest it has (\"did you mean\").", "",
             "The model's decision threshold is not a vehicle setting: it is part of the signed model card, chosen "
             "with the model on real drives, so that no file beside the model can change what counts as a blind "
             "spot.", ""]

    def walk(node: dict[str, Any], name: str) -> None:
        leaves = {k: v for k, v in node["properties"].items() if v["type"] != "object"}
        lines.extend([f"## `[{name}]`", ""])
        if node.get("description"):
            lines.extend([node["description"], ""])
        if leaves:
            lines.extend(["| key | default | kind | range | what it does |", "|---|---|---|---|---|"])
            for key, v in leaves.items():
                what = v.get("description", "") if v.get("description") != node.get("description") else ""
                lines.append(f"| `{key}` | {cell_default(v)} | {cell_kind(v)} | {cell_range(v)} | {what} |")
            lines.append("")
        for key, v in node["properties"].items():
            if v["type"] == "object":
                walk(v, f"{name}.{key}")

    for name, node in schema()["properties"].items():
        walk(node, name)
    return "\n".join(lines).rstrip() + "\n"


def generated(checkout: Path) -> dict[Path, str]:
    """Every file of ``checkout`` made from the settings, with its text: the JSON Schema, the reference page and
    the docs' settings table (its block in ``docs/runtime.md``)."""
    import json

    from bsn_edge.runtime.config_file import settings_table

    runtime_page = checkout / "docs" / "runtime.md"
    page = runtime_page.read_text(encoding="utf-8")
    start = page.index("\n", page.index(TABLE_START)) + 1
    end = page.index(TABLE_END)
    return {SCHEMA_FILE: json.dumps(schema(), indent=1) + "\n",
            checkout / "docs" / "settings.md": reference_page(),
            runtime_page: page[:start] + "\n".join(settings_table()) + "\n" + page[end:]}


TABLE_START, TABLE_END = "<!-- settings table:", "<!-- end of settings table -->"


CHECKOUT = Path(__file__).resolve().parents[2]     # the source tree this package sits in


def main(argv: list[str] | None = None, checkout: Path = CHECKOUT) -> int:
    """Write the files of ``checkout`` made from the settings (``--check``: write nothing, exit 1 naming those
    that are stale)."""
    import sys

    check = (sys.argv[1:] if argv is None else argv) == ["--check"]
    stale = []
    for path, text in generated(checkout).items():
        if path.read_text(encoding="utf-8") != text:
            stale.append(path)
            if not check:
                path.write_text(text, encoding="utf-8")
    for path in stale:
        print(f"{path}: {'stale: regenerate it with python -m bsn_edge.runtime.config_schema' if check else 'written'}")
    return 1 if check and stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
