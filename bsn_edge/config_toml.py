"""Configuration as TOML sections of frozen dataclasses, with ``--set section.key=value`` overrides.

One mechanism for every config of the project (training's, the runtime's): a section is a dataclass,
a nested table is a dataclass field of it (``[alerts.caution]``), values are coerced to the field's
type, and an unknown section or key, a value of the wrong kind or one out of range (the dataclass's own
``ValueError``) is refused naming the key and where it came from (the file or ``--set``).
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

KINDS = {int: "a whole number", float: "a number", str: "a string", bool: "true or false", tuple: "a list"}


def parse_override(text: str) -> tuple[list[str], Any]:
    """``section.key=value`` (or ``section.sub.key=value``) -> (the dotted path, value); the value is read
    as TOML if it can be."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise ValueError(f"override {text!r} must look like section.key=value (e.g. train.steps=100)")
    dotted, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return [part.strip() for part in dotted.split(".")], value


def read_toml(path: str | Path | None) -> dict[str, Any]:
    """A TOML file's tables ({} without a path); ``FileNotFoundError`` or ``ValueError`` naming it."""
    if path is None:
        return {}
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"config {p} not found")
    try:
        return tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{p}: invalid TOML: {e}") from None


def merge_overrides(raw: dict[str, Any], overrides: list[str] | tuple[str, ...]) -> set[str]:
    """Apply ``overrides`` onto ``raw`` in place; the dotted keys they set (to say where a bad one came from)."""
    given = set()
    for ov in overrides:
        path, value = parse_override(ov)
        table = raw
        for part in path[:-1]:
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise ValueError(f"--set {ov}: {'.'.join(path[:-1])} is a value, not a table")
        table[path[-1]] = value
        given.add(".".join(path))
    return given


def coerce(cls: type, key: str, value: Any) -> Any:
    """``value`` as field ``key`` of ``cls`` wants it (a TOML int for a float, a list for a tuple...)."""
    default = default_of(cls, key)
    if isinstance(default, tuple) and isinstance(value, list | tuple):
        return tuple(value)
    if isinstance(default, bool):
        if isinstance(value, str):
            return value.lower() in ("1", "true", "yes", "on")
        return bool(value)
    if isinstance(default, float) and isinstance(value, int | str) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, int) and isinstance(value, str):
        return int(value)
    return value


def default_of(cls: type, key: str) -> Any:
    f = {f.name: f for f in dataclasses.fields(cls)}[key]
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def build(cls: type, values: dict[str, Any], name: str, where: str, given: set[str]) -> Any:
    """An instance of dataclass ``cls`` from ``values`` (a TOML table called ``name``), nested tables for
    its dataclass fields; ``ValueError`` naming the key and ``where`` (``--set`` for keys in ``given``)."""
    names = {f.name for f in dataclasses.fields(cls)}
    bad = sorted(set(values) - names)
    if bad:
        raise ValueError(f"unknown key(s) {bad} in [{name}]; valid: {', '.join(sorted(names))}")
    out = {}
    for key, value in values.items():
        dotted = f"{name}.{key}"
        src = "--set" if dotted in given else where
        default = default_of(cls, key)
        if dataclasses.is_dataclass(default):
            if not isinstance(value, dict):
                inner = ", ".join(f.name for f in dataclasses.fields(default))
                raise ValueError(f"{dotted} ({src}) must be a table of {inner}")
            merged = {**{f.name: getattr(default, f.name) for f in dataclasses.fields(default)}, **value}
            out[key] = build(type(default), merged, dotted, where, given)
            continue
        try:
            out[key] = coerce(cls, key, value)
        except ValueError:
            kind = KINDS.get(type(default), type(default).__name__)
            raise ValueError(f"{dotted} = {value!r} ({src}) must be {kind}") from None
    try:
        return cls(**out)
    except ValueError as e:             # the dataclass's own check, which names its fields
        src = "--set" if any(k.startswith(f"{name}.") for k in given) else where
        raise ValueError(f"[{name}] ({src}): {e}") from None
