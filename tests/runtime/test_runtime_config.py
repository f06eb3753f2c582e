"""The runtime's settings from one file: a sector edge and a smoothing time changed in it reach the bus
(decoded from the CAN log with cantools and python-can's reader, not the project's decoder), the shipped
file is the defaults, and a key the runtime does not have or a value out of range is refused naming it."""

import json
from pathlib import Path

import can
import cantools
import pytest

from bsn_edge.alerts.can_codec import DBC_PATH
from bsn_edge.cli import run as run_cli
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.runtime.config_file import load_runtime_config
from bsn_edge.runtime.loop import RuntimeConfig

ROOT = Path(__file__).resolve().parents[2]


def _hazards(log: Path) -> list[dict]:
    db = cantools.database.load_file(str(DBC_PATH))
    out = []
    with can.LogReader(str(log)) as reader:
        for m in reader:
            if m.arbitration_id == db.get_message_by_name("BSN_Hazard").frame_id:
                out.append(db.decode_message(m.arbitration_id, bytes(m.data)))
    return out[:-1]            # the last says UNAVAILABLE's nothing-known


def _run(clip: Path, tmp_path: Path, name: str, *extra: str) -> list[dict]:
    log = tmp_path / f"{name}.log"
    assert run_cli.main(["--model", str(DEFAULT_MODEL), "--source", str(clip / "video.mp4"), "--calib",
                         str(clip / "calibration.json"), "--can-log", str(log), "--summary",
                         str(tmp_path / f"{name}.json"), *extra]) == 0
    return _hazards(log)


def test_the_shipped_file_is_the_defaults():
    assert load_runtime_config(ROOT / "configs" / "runtime.toml") == RuntimeConfig()


def test_a_sector_edge_and_a_smoothing_time_from_the_file_reach_the_bus(setup, tmp_path):
    _, clip = setup
    plain = _run(clip, tmp_path, "plain", "--set", "alerts.tau_s=0")
    assert max(h["Centre_Score"] for h in plain) > 0, "the default marks blind spots ahead on this clip"
    assert len({h["Centre_Score"] for h in plain}) > 1, "unsmoothed, the score moves from frame to frame"
    cfg = tmp_path / "vehicle.toml"
    # LEFT and CENTRE end left of the picture's 40 degrees: every pixel is RIGHT's; and a smoothing time so
    # long that each score stays where its first frame put it (1 - exp(-0.1 / 1e5) ~ 1e-6 a cycle)
    cfg.write_text("[sectors]\nleft_edge_deg = -88.0\nright_edge_deg = -87.5\n\n[alerts]\ntau_s = 100000.0\n")
    tuned = _run(clip, tmp_path, "tuned", "--config", str(cfg))
    assert all(h["Left_Score"] == 0 and h["Centre_Score"] == 0 for h in tuned)
    assert all(h["Left_Distance"] == 63.5 and h["Centre_Distance"] == 63.5 for h in tuned), "nothing in range"
    assert max(h["Right_Score"] for h in tuned) > 0
    assert len({h["Right_Score"] for h in tuned}) == 1, "the first frame's score, held"
    summary = json.loads((tmp_path / "tuned.json").read_text())
    assert summary["settings"]["sectors"]["left_edge_deg"] == -88.0 and summary["settings"]["alerts"]["tau_s"] == 1e5
    assert summary["settings_digest"] != json.loads((tmp_path / "plain.json").read_text())["settings_digest"]


@pytest.mark.parametrize("setting,says", [
    ("sectors.left_edge=-15", "unknown key(s) ['left_edge'] in [sectors]; valid: full_area, left_edge_deg"),
    ("alerts.caution.on=2", "[alerts.caution] (--set): need 0 <= off < on <= 1"),
    ("runtime.cycle_s=abc", "runtime.cycle_s = 'abc' (--set) must be a number"),
    ("wheels.count=4", "unknown section(s) ['wheels']; valid: runtime, sectors, alerts, health"),
])
def test_a_bad_setting_is_refused_naming_it_and_the_bus_says_unavailable(setup, tmp_path, capsys, setting, says):
    _, clip = setup
    log = tmp_path / "bad.log"
    assert run_cli.main(["--model", str(DEFAULT_MODEL), "--source", str(clip / "video.mp4"), "--can-log", str(log),
                         "--set", setting]) == 2
    assert says in capsys.readouterr().err
    db = cantools.database.load_file(str(DBC_PATH))
    with can.LogReader(str(log)) as reader:
        states = [db.decode_message(m.arbitration_id, bytes(m.data))["System_State"] for m in reader
                  if m.arbitration_id == db.get_message_by_name("BSN_Status").frame_id]
    assert [str(s) for s in states] == ["UNAVAILABLE"]


def _tables(table: dict, prefix: str = "") -> list[tuple[str, dict]]:
    """Every table of a parsed TOML file, nested ones too, by dotted name."""
    out = []
    for key, value in table.items():
        if isinstance(value, dict):
            out.append((prefix + key, value))
            out += _tables(value, f"{prefix}{key}.")
    return out


def _shipped_tables() -> list[tuple[str, dict]]:
    import tomllib

    return _tables(tomllib.loads((ROOT / "configs" / "runtime.toml").read_text()))


def test_the_walk_finds_every_table_of_the_shipped_file_nested_ones_too():
    names = [name for name, _ in _shipped_tables()]
    assert {"runtime", "sectors", "alerts", "alerts.caution", "alerts.warning", "health"} <= set(names)


@pytest.mark.parametrize("table", [name for name, _ in _shipped_tables()])
def test_an_unknown_key_in_any_table_nested_ones_too_is_refused_from_set_and_from_a_file(table, tmp_path):
    """A typo of a real key (its name with one letter doubled), in each table of the shipped file: dropped
    instead, the user's setting would silently never take effect."""
    values = dict(_shipped_tables())[table]
    real = next(k for k, v in values.items() if not isinstance(v, dict))
    typo = real[:-1] + real[-1] * 2
    with pytest.raises(ValueError, match=rf"unknown key\(s\) \['{typo}'\] in \[{table}\]"):
        load_runtime_config(overrides=[f"{table}.{typo}=1"])
    path = tmp_path / "typo.toml"
    path.write_text(f"[{table}]\n{typo} = 1\n")
    with pytest.raises(ValueError, match=rf"unknown key\(s\) \['{typo}'\] in \[{table}\]"):
        load_runtime_config(path)


TRAINING_CONFIGS = sorted(p.name for p in (ROOT / "configs").glob("*.toml") if p.name != "runtime.toml")


@pytest.mark.parametrize("config", TRAINING_CONFIGS)
def test_an_unknown_key_in_any_training_table_is_refused_too(config):
    """The training configs share the loader: a typo in each of their tables is refused by name."""
    import tomllib

    from bsn_edge.train.config import load_config

    for table, values in _tables(tomllib.loads((ROOT / "configs" / config).read_text())):
        real = next(k for k, v in values.items() if not isinstance(v, dict))
        typo = real + "x"
        with pytest.raises(ValueError, match=rf"unknown key\(s\) \['{typo}'\] in \[{table}\]"):
            load_config(ROOT / "configs" / config, [f"{table}.{typo}=1"])
