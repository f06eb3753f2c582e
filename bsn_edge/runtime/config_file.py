"""The runtime's settings in one TOML file: what an integrator tunes without code.

:data:`DEFAULTS_FILE` (in the package, so every install has it; ``configs/runtime.toml`` in a checkout,
``bsn-run --print-config`` prints it) holds every one at its default, with what it does:

- ``[runtime]``: the loop (``cycle_s``, ``warmup``, ``overlap``, ``in_flight``, ``feeder_nice``, ``threads``,
  ``spin``);
- ``[sectors]``: the sector layout (each sector's name and the bearing it ends at) and how far blind spots
  count (:class:`SectorConfig`);
- ``[alerts]``: smoothing (``tau_s``) and each level's rule (``[alerts.caution]``, ``[alerts.warning]``:
  ``on``, ``off``, ``delay_s``, ``hold_s``; :class:`AlertConfig`);
- ``[health]``: when the status says DEGRADED or UNAVAILABLE (:class:`HealthConfig`);
- ``[bus]``: the buses, the serial baud rate, the sends' timeouts and when a bus is down (:class:`BusConfig`);
- ``[messages]``: each message every so many cycles (:class:`MessageRates`);
- ``[source]``: when a camera or stream is lost and how it is brought back (:class:`SourceConfig`);
- ``[calibration]``: online calibration's share of the cores (:class:`CalibrationConfig`);
- ``[visibility]``: the camera-health check's thresholds and times (:class:`VisibilityConfig`).

``bsn-run --config FILE --set alerts.tau_s=0.5`` reads it with the mechanism the training config
has (:mod:`bsn_edge.config_toml`): a key the runtime does not have, or a value out of range, is refused
naming the key. The resolved settings and their digest go into the run's summary.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

from bsn_edge.alerts.bus_config import BusConfig, MessageRates
from bsn_edge.alerts.health import HealthConfig
from bsn_edge.alerts.sectors import SectorConfig
from bsn_edge.alerts.state_machine import AlertConfig
from bsn_edge.config_toml import build, merge_overrides, read_toml, shown, unknown
from bsn_edge.runtime.settings import RuntimeConfig
from bsn_edge.runtime.source_config import CalibrationConfig, SourceConfig
from bsn_edge.runtime.visibility import VisibilityConfig

DEFAULTS_FILE = Path(__file__).with_name("runtime.toml")
SCHEMA_FILE = DEFAULTS_FILE.with_name("runtime.schema.json")     # written by config_schema, checked by a test
NESTED: dict[str, type] = {"sectors": SectorConfig, "alerts": AlertConfig, "health": HealthConfig,
                           "bus": BusConfig, "messages": MessageRates, "source": SourceConfig,
                           "calibration": CalibrationConfig, "visibility": VisibilityConfig}
LOOP = "runtime"


def with_ranges(path: Path = DEFAULTS_FILE) -> str:
    """The settings file as ``bsn-run --print-config`` prints it: each key's line ends with its range and unit,
    taken from the setting's declaration (the file itself carries none, so no range is written twice)."""
    from bsn_edge.runtime.config_schema import KEY_LINE, TABLE_LINE, cell_range, leaves

    nodes = dict(leaves())
    out, table = [], ""
    for line in path.read_text(encoding="utf-8").splitlines():
        if m := TABLE_LINE.match(line.strip()):
            table = m.group(1)
        elif (m := KEY_LINE.match(line.strip())) and (span := cell_range(nodes.get(f"{table}.{m.group(1)}", {}))):
            line += f" ({span})" if "#" in line else f"  # ({span})"
        out.append(line)
    return "\n".join(out) + "\n"


def load_runtime_config(path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = ()
                        ) -> RuntimeConfig:
    """The runtime's settings: the defaults, then the file at ``path``, then ``overrides``
    (``section.key=value``); ``ValueError`` or ``FileNotFoundError`` naming what is wrong."""
    raw = read_toml(path)
    given = merge_overrides(raw, overrides, example="alerts.tau_s=0.5")
    where = str(path) if path is not None else "--set"
    valid = [LOOP, *NESTED]
    sections = sorted(set(raw) - set(valid))
    if sections:
        raise ValueError(unknown(sections, valid, "section(s)"))
    for name, table in raw.items():
        if not isinstance(table, dict):      # `runtime = 5`, `[[runtime]]`: a value or a list, not a table
            raise ValueError(f"[{name}] ({where}) must be a table of settings, got {type(table).__name__}")
    _old_edges(raw.get("sectors", {}), where)
    loop_keys = {f.name for f in dataclasses.fields(RuntimeConfig)} - set(NESTED)
    loop = raw.get(LOOP, {})
    bad = sorted(set(loop) - loop_keys)
    if bad:
        raise ValueError(unknown(bad, loop_keys, f"key(s) in [{LOOP}]"))
    parts = {name: build(cls, raw[name], name, where, given) for name, cls in NESTED.items() if name in raw}
    return dataclasses.replace(build(RuntimeConfig, loop, LOOP, where, given), **parts)


OLD_EDGES = ("left_edge_deg", "right_edge_deg")


def _old_edges(sectors: dict[str, Any], where: str) -> None:
    """A file of the time before layouts (``left_edge_deg``, ``right_edge_deg``): refused with the layout line that
    says the same, so the user's edges are not lost to a default."""
    if not any(k in sectors for k in OLD_EDGES):
        return
    left, right = (sectors.get(k, d) for k, d in zip(OLD_EDGES, (-12.0, 12.0), strict=True))
    edges = ", ".join(f"{k} = {shown(sectors[k])}" for k in OLD_EDGES if k in sectors)
    raise ValueError(f"[sectors] ({where}): {edges}: the sectors are now a layout; write instead "
                     f'layout = [{{ name = "LEFT", to_deg = {shown(left)} }}, {{ name = "CENTRE", to_deg = '
                     f'{shown(right)} }}, {{ name = "RIGHT" }}]')


def to_dict(cfg: RuntimeConfig) -> dict[str, Any]:
    """The settings as the file lays them out."""
    d = dataclasses.asdict(cfg)
    return {LOOP: {k: v for k, v in d.items() if k not in NESTED}, **{k: d[k] for k in NESTED}}


def digest(cfg: RuntimeConfig) -> str:
    """Short sha256 of the resolved settings: two runs with the same digest were tuned alike."""
    return hashlib.sha256(json.dumps(to_dict(cfg), sort_keys=True).encode()).hexdigest()[:16]


def settings_table() -> list[str]:
    """Every setting a vehicle file holds, with its default, kind and range, as Markdown table rows in
    the file's order (the docs' settings table is this one, checked by a test): read off the JSON Schema
    (:func:`~bsn_edge.runtime.config_schema.schema`), the one place a setting's kind and range are written
    out, so the table, the schema and the reference page cannot say two things."""
    from bsn_edge.runtime.config_schema import cell_default, cell_kind, cell_range, leaves

    return ["| setting | default | kind | range |", "|---|---|---|---|"] + [
        f"| `{dotted}` | {cell_default(v)} | {cell_kind(v)} | {cell_range(v)} |" for dotted, v in leaves()]
