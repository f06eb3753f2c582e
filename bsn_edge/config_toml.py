"""Configuration as TOML sections of frozen dataclasses, with ``--set section.key=value`` overrides.

One mechanism for every config of the project (training's, the runtime's): a section is a dataclass,
a nested table is a dataclass field of it (``[alerts.caution]``), values must be of the field's kind
(nothing is coerced from a string; numbers are finite),
and an unknown section or key, a value of the wrong kind or one out of range (the dataclass's own
``ValueError``) is refused naming the key and where it came from (the file or ``--set``).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
from pathlib import Path
from typing import Any

from bsn_edge.user_file import read_user_file

KINDS = {int: "a whole number", float: "a finite number", str: "a string", bool: "true or false", tuple: "a list"}


def parse_override(text: str, example: str) -> tuple[list[str], Any]:
    """``section.key=value`` (or ``section.sub.key=value``) -> (the dotted path, value); the value is read
    as TOML if it can be. ``example``: an override of the caller's own, shown when ``text`` is not one."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise ValueError(f"override {text!r} must look like section.key=value (e.g. {example})")
    dotted, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    except RecursionError:
        raise ValueError(f"override {text[:60]!r}: nested too deep") from None
    return [part.strip() for part in dotted.split(".")], value


def read_toml(path: str | Path | None) -> dict[str, Any]:
    """A TOML file's tables ({} without a path); ``FileNotFoundError`` or ``ValueError`` naming it."""
    if path is None:
        return {}
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"config {p} is a folder, not a TOML file")
    if not p.exists():
        raise FileNotFoundError(f"config {p} not found")
    data = read_user_file(p, "settings")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"{p}: not UTF-8 text (byte {e.start} is {data[e.start]:#04x}); a TOML file is "
                         "UTF-8") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{p}: invalid TOML: {e}") from None
    except RecursionError:
        raise ValueError(f"{p}: invalid TOML: nested too deep") from None


def merge_overrides(raw: dict[str, Any], overrides: list[str] | tuple[str, ...], example: str) -> set[str]:
    """Apply ``overrides`` onto ``raw`` in place; the dotted keys they set (to say where a bad one came from).
    ``example``: a valid override of the caller's settings, for the message when one is malformed."""
    given = set()
    for ov in overrides:
        path, value = parse_override(ov, example)
        table = raw
        for part in path[:-1]:
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise ValueError(f"--set {ov}: {'.'.join(path[:-1])} is a value, not a table")
        table[path[-1]] = value
        given.add(".".join(path))
    return given


def coerce(cls: type, key: str, value: Any) -> Any:
    """``value`` as field ``key`` of ``cls`` wants it, strictly: a whole number where the default is
    one, a number (a TOML integer taken as a float) where it is a float, true or false where it is a
    boolean, a list where it is a tuple (its items likewise); nothing is read out of a string, and a
    number is finite (a :func:`setting` with no default is a number). ``ValueError`` (from the caller's
    message) for anything else."""
    default = default_of(cls, key)
    meta = _field(cls, key).metadata
    if default is None and "range" in meta:
        default = 0.0
    if isinstance(value, meta.get("also", ())) and not isinstance(value, bool):
        return value                        # a spelling the dataclass itself turns into its kind
    return _strict(default, value)


def _strict(default: Any, value: Any) -> Any:
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(value)
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(value)
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ValueError(value)
        return float(value)
    if isinstance(default, tuple):
        if not isinstance(value, list | tuple):
            raise ValueError(value)
        if not default:                                   # a list of any length, of anything
            return tuple(value)
        if _numbers(default) and len(value) != len(default):   # a size, a pair: its length is its meaning
            raise ValueError(value)
        return tuple(_strict(default[0], v) for v in value)
    if isinstance(default, str) and not isinstance(value, str):
        raise ValueError(value)
    return value


def _numbers(default: tuple) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in default)


def setting(default: Any, lo: float, hi: float, unit: str = "") -> Any:
    """A dataclass field whose value must lie in ``[lo, hi]`` (``unit`` said with it): held by
    :func:`check_fields` in the dataclass's ``__post_init__``, so a value made in code is held too.
    ``dataclasses.MISSING``: a field with no default."""
    return dataclasses.field(default=default, metadata={"range": (lo, hi), "unit": unit})


def _range_of(cls: type, key: str) -> str:
    """`` in [lo, hi] unit`` for a :func:`setting` field, else empty."""
    meta = _field(cls, key).metadata
    if "range" not in meta:
        return ""
    lo, hi = meta["range"]
    return f" in [{lo:g}, {hi:g}]" + (f" {meta['unit']}" if meta["unit"] else "")


def shown(value: Any, most: int = 40) -> str:
    """A value as a message shows it: its repr, cut to ``most`` characters with its length said (a 400-digit
    number or a list nested 5,000 deep is named, not printed)."""
    text = repr(value)
    return text if len(text) <= most else f"{text[:most // 2]}... ({len(text)} characters)"


def check_fields(obj: Any) -> None:
    """``ValueError`` naming the first field of dataclass ``obj`` of the wrong kind (a boolean for a
    number, a float for a whole number, anything not finite) or outside its :func:`setting` range."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if isinstance(f.default, bool) and not isinstance(value, bool):
            raise ValueError(f"{f.name} = {value!r} must be true or false")
        if "range" not in f.metadata:
            continue
        lo, hi = f.metadata["range"]
        unit = f" {f.metadata['unit']}" if f.metadata["unit"] else ""
        whole = isinstance(f.default, int) and not isinstance(f.default, bool)
        if isinstance(value, bool) or not isinstance(value, int | float) or (whole and not isinstance(value, int)):
            raise ValueError(f"{f.name} = {value!r} must be {'a whole number' if whole else 'a finite number'}"
                             f"{_range_of(type(obj), f.name)}")
        # a 400-digit whole number is compared as a whole number (math.isfinite would overflow on it)
        if not ((isinstance(value, int) or math.isfinite(value)) and lo <= value <= hi):
            raise ValueError(f"{f.name} = {shown(value)} is outside [{lo:g}, {hi:g}]{unit}")


def _field(cls: type, key: str) -> dataclasses.Field:
    return next(f for f in dataclasses.fields(cls) if f.name == key)


def default_of(cls: type, key: str) -> Any:
    f = _field(cls, key)
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def unknown(bad: list[str], valid: list[str] | set[str], what: str) -> str:
    """The refusal of keys (or sections) ``bad`` that ``what`` does not have: each with the valid name it is
    closest to, when one is close ("did you mean"), then every valid name."""
    hints = []
    for b in bad:
        close = difflib.get_close_matches(b, sorted(valid), n=1, cutoff=0.6)
        hints.append(f"{b!r} (did you mean {close[0]!r}?)" if close else repr(b))
    return f"unknown {what}: {', '.join(hints)}; valid: {', '.join(sorted(valid))}"


def build(cls: type, values: dict[str, Any], name: str, where: str, given: set[str]) -> Any:
    """An instance of dataclass ``cls`` from ``values`` (a TOML table called ``name``), nested tables for
    its dataclass fields; ``ValueError`` naming the key and ``where`` (``--set`` for keys in ``given``)."""
    names = {f.name for f in dataclasses.fields(cls)}
    bad = sorted(set(values) - names)
    if bad:
        raise ValueError(unknown(bad, names, f"key(s) in [{name}]"))
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
        except (ValueError, OverflowError, TypeError):      # a 400-digit number is no finite setting
            kind = KINDS.get(type(default), "a finite number" if _range_of(cls, key) else type(default).__name__)
            if isinstance(default, tuple) and default and _numbers(default):
                kind = f"a list of {len(default)} numbers"
            raise ValueError(f"{dotted} = {shown(value)} ({src}) must be {kind}{_range_of(cls, key)}") from None
    try:
        return cls(**out)
    except (ValueError, OverflowError, TypeError) as e:     # the dataclass's own check, which names its fields
        src = "--set" if any(k.startswith(f"{name}.") for k in given) else where
        raise ValueError(f"[{name}] ({src}): {e}") from None
