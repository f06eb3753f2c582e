"""The runtime's settings from one file: a sector edge and a smoothing time changed in it reach the bus
(decoded from the CAN log with cantools and python-can's reader, not the project's decoder), the shipped
file is the defaults, and a key the runtime does not have or a value out of range is refused naming it."""

import itertools
import json
from pathlib import Path

import can
import cantools
import pytest

from bsn_edge.alerts.can_codec import DBC_PATH
from bsn_edge.cli import run as run_cli
from bsn_edge.cli.common import CHECKOUT
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.runtime.config_file import load_runtime_config
from bsn_edge.runtime.settings import RuntimeConfig

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
    # LEFT and CENTRE end left of the picture's 40 degrees: every pixel is RIGHT's; and the longest smoothing
    # time a vehicle may set, 2 s: a cycle moves a score by at most 1 - exp(-0.1 / 2) = 4.9 % of the way
    cfg.write_text('[sectors]\nlayout = [{ name = "LEFT", to_deg = -88.0 }, { name = "CENTRE", to_deg = -87.5 }, '
                   '{ name = "RIGHT" }]\n\n[alerts]\ntau_s = 2.0\n')
    tuned = _run(clip, tmp_path, "tuned", "--config", str(cfg))
    assert all(h["Left_Score"] == 0 and h["Centre_Score"] == 0 for h in tuned)
    assert all(h["Left_Distance"] == 63.5 and h["Centre_Distance"] == 63.5 for h in tuned), "nothing in range"
    assert max(h["Right_Score"] for h in tuned) > 0
    steps = [abs(b["Right_Score"] - a["Right_Score"]) for a, b in itertools.pairwise(tuned)]
    assert len({h["Right_Score"] for h in tuned}) > 1 and max(steps) <= 0.049 + 1 / 127, "smoothed over 2 s"
    summary = json.loads((tmp_path / "tuned.json").read_text())
    assert summary["settings"]["sectors"]["layout"][0] == {"name": "LEFT", "to_deg": -88.0}
    assert summary["settings"]["alerts"]["tau_s"] == 2.0
    assert summary["settings_digest"] != json.loads((tmp_path / "plain.json").read_text())["settings_digest"]


@pytest.mark.parametrize("setting,says", [
    ("sectors.layot=[]", "unknown key(s) in [sectors]: 'layot' (did you mean 'layout'?)"),
    ("alerts.caution.on=2", "[alerts.caution] (--set): on = 2.0 is outside [0.05, 0.9]"),
    ("runtime.cycle_s=abc", "runtime.cycle_s = 'abc' (--set) must be a finite number in [0.01, 1] s"),
    ("wheels.count=4",
     "unknown section(s): 'wheels'; valid: alerts, bus, calibration, health, messages, runtime, sectors, source"),
])
def test_a_bad_setting_is_refused_naming_it_and_the_bus_says_unavailable(setup, tmp_path, capsys, setting, says):
    _, clip = setup
    log, summary = tmp_path / "bad.log", tmp_path / "bad.json"
    assert run_cli.main(["--model", str(DEFAULT_MODEL), "--source", str(clip / "video.mp4"), "--can-log", str(log),
                         "--summary", str(summary), "--set", setting]) == 2
    assert says in capsys.readouterr().err
    said = json.loads(summary.read_text())
    assert said["frames"] == 0 and says in said["refused"], "the summary says why nothing ran"
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
    with pytest.raises(ValueError, match=rf"unknown key\(s\) in \[{table}\]: '{typo}' \(did you mean '{real}'\?\)"):
        load_runtime_config(overrides=[f"{table}.{typo}=1"])
    path = tmp_path / "typo.toml"
    path.write_text(f"[{table}]\n{typo} = 1\n")
    with pytest.raises(ValueError, match=rf"unknown key\(s\) in \[{table}\]: '{typo}' \(did you mean '{real}'\?\)"):
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
        with pytest.raises(ValueError, match=rf"unknown key\(s\) in \[{table}\]: '{typo}'"):
            load_config(ROOT / "configs" / config, [f"{table}.{typo}=1"])


# every value the integrators' audit found accepted, each able to silence the bus or crash the run
NO_VEHICLE_CAN_USE = [
    ("alerts.tau_s=nan", "alerts.tau_s = nan (--set) must be a finite number in [0, 2] s"),
    ("runtime.cycle_s=inf", "runtime.cycle_s = inf (--set) must be a finite number in [0.01, 1] s"),
    ("runtime.cycle_s=1e9", "cycle_s = 1000000000.0 is outside [0.01, 1] s"),
    ("alerts.caution.delay_s=inf", "alerts.caution.delay_s = inf (--set) must be a finite number in [0, 5] s"),
    ("alerts.caution.delay_s=1e6", "delay_s = 1000000.0 is outside [0, 5] s"),
    ("health.deadline_s=inf", "health.deadline_s = inf (--set) must be a finite number in [0.05, 1] s"),
    ("health.deadline_s=nan", "health.deadline_s = nan (--set) must be a finite number in [0.05, 1] s"),
    ("sectors.range_m=inf", "sectors.range_m = inf (--set) must be a finite number in [10, 200] m"),
    ("alerts.tau_s=inf", "alerts.tau_s = inf (--set) must be a finite number in [0, 2] s"),
    ("health.fps_floor=nan", "health.fps_floor = nan (--set) must be a finite number in [0, 60] frames/s"),
    ("runtime.overlap=ture", "runtime.overlap = 'ture' (--set) must be true or false"),
    ("alerts.tau_s=true", "alerts.tau_s = True (--set) must be a finite number in [0, 2] s"),
    ('alerts.tau_s="0.5"', "alerts.tau_s = '0.5' (--set) must be a finite number in [0, 2] s"),
    ("runtime.warmup=2.5", "runtime.warmup = 2.5 (--set) must be a whole number in [0, 100] inferences"),
    ("runtime.in_flight=1.5", "runtime.in_flight = 1.5 (--set) must be a whole number in [1, 4] frames"),
    ("sectors.range_m=[1,2]", "sectors.range_m = [1, 2] (--set) must be a finite number in [10, 200] m"),
    ("sectors.layout=5", "sectors.layout = 5 (--set) must be a list"),
    ('sectors.layout=[{name="LEFT",to_deg=5},{name="LEFT"}]', "[sectors] (--set): layout names 'LEFT' twice"),
    ('sectors.layout=[{name="A",to_deg=5},{name="B",to_deg=1},{name="C"}]',
     "[sectors] (--set): layout[1].to_deg = 1 (B) must be right of the sector before it (5)"),
    ('sectors.layout=[{name="A",to_deg=5},{name="B",to_deg=9}]',
     "[sectors] (--set): layout[1] (B) is the last sector: it runs to the field's edge, so it has no to_deg"),
    ('sectors.layout=[{name="A",to_deg=89},{name="B"}]',
     "[sectors] (--set): layout[0].to_deg = 89 (A) must be a bearing between -89 and 89 degrees"),
    ('sectors.layout=[{name="left",to_deg=0},{name="B"}]', "[sectors] (--set): layout[0].name = 'left' must be"),
    ('sectors.layout=[{name="A",edge=0},{name="B"}]',
     "[sectors] (--set): layout[0] has unknown key(s) 'edge'; a sector has name and to_deg"),
    ("sectors.left_edge_deg=-15", "[sectors] (--set): left_edge_deg = -15: the sectors are now a layout; write "
     'instead layout = [{ name = "LEFT", to_deg = -15 }, { name = "CENTRE", to_deg = 12.0 }, { name = "RIGHT" }]'),
    ("alerts.caution.hold_s=true", "alerts.caution.hold_s = True (--set) must be a finite number in [0, 10] s"),
    ("alerts.warning.on=1.0", "[alerts.warning] (--set): on = 1.0 is outside [0.05, 0.9]"),
    ("sectors.full_area=1", "[sectors] (--set): full_area = 1.0 is outside [0.001, 0.05]"),
]


@pytest.mark.parametrize("setting,says", NO_VEHICLE_CAN_USE)
def test_every_setting_no_vehicle_can_use_is_refused_naming_key_and_value(setting, says):
    with pytest.raises(ValueError) as e:
        load_runtime_config(overrides=[setting])
    assert says in str(e.value)


def test_settings_made_in_code_are_held_to_the_same_ranges():
    from bsn_edge.alerts.health import HealthConfig
    from bsn_edge.alerts.state_machine import LevelRule

    with pytest.raises(ValueError, match=r"deadline_s = inf is outside \[0.05, 1\] s"):
        HealthConfig(deadline_s=float("inf"))
    with pytest.raises(ValueError, match="must be true or false"):
        RuntimeConfig(overlap="yes")
    with pytest.raises(ValueError, match=r"delay_s = nan is outside"):
        LevelRule(on=0.5, off=0.2, delay_s=float("nan"), hold_s=1.0)


def _fields_and_values():
    """Every runtime setting's dotted key, and values drawn from every kind TOML can hold."""
    from hypothesis import strategies as st

    keys = [f"{table}.{key}" for table, values in _shipped_tables() for key, v in values.items()
            if not isinstance(v, dict)]
    scalars = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**12, 10**12), st.booleans(),
                        st.text(max_size=6))
    values = st.one_of(scalars, st.lists(scalars, max_size=3))
    return st.lists(st.tuples(st.sampled_from(keys), values), min_size=1, max_size=4)


def _toml(value) -> str:
    import json as _json
    import math

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, str):
        return _json.dumps(value)
    return repr(value)


def _within(cfg) -> None:
    """Every number of a loaded config in its field's range, of its field's kind, finite."""
    import dataclasses
    import math

    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if dataclasses.is_dataclass(v):
            _within(v)
        elif "range" in f.metadata:
            lo, hi = f.metadata["range"]
            assert not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v) and lo <= v <= hi, f.name
        elif isinstance(f.default, bool):
            assert isinstance(v, bool), f.name


def test_random_settings_are_refused_or_every_value_is_in_its_range():
    """Property: whatever values a file or --set gives any keys, the loader either refuses them with a
    ValueError that names a key, or returns settings whose every value is of its kind, finite and in range."""
    from hypothesis import given, settings

    @settings(max_examples=300, deadline=None)
    @given(_fields_and_values())
    def check(pairs):
        overrides = [f"{key}={_toml(value)}" for key, value in pairs]
        try:
            cfg = load_runtime_config(overrides=overrides)
        except ValueError as e:
            assert any(key.split(".")[-1] in str(e) for key, _ in pairs), str(e)
            return
        _within(cfg)

    check()


def test_the_docs_settings_table_is_the_one_the_settings_make():
    from bsn_edge.runtime.config_file import settings_table

    page = (ROOT / "docs" / "runtime.md").read_text()
    start = page.index("<!-- settings table:")
    block = page[page.index("\n", start) + 1:page.index("<!-- end of settings table -->")]
    assert block.strip().splitlines() == settings_table()
    shipped = {f"{t}.{k}" for t, values in _shipped_tables() for k, v in values.items() if not isinstance(v, dict)}
    assert {row.split("`")[1] for row in settings_table()[2:]} == shipped, "the shipped file lists every setting"


def test_a_config_that_is_a_folder_or_not_utf8_is_named_as_such(tmp_path):
    with pytest.raises(ValueError, match=r"is a folder, not a TOML file"):
        load_runtime_config(tmp_path)
    latin = tmp_path / "latin.toml"
    latin.write_bytes("# Fahrzeug für die Stadt\n[alerts]\ntau_s = 0.5\n".encode("latin-1"))
    with pytest.raises(ValueError, match=rf"{latin}: not UTF-8 text \(byte 12 is 0xfc\)"):
        load_runtime_config(latin)
    with pytest.raises(FileNotFoundError, match="not found"):
        load_runtime_config(tmp_path / "none.toml")


def test_a_malformed_set_is_answered_with_an_example_of_the_runtimes_own():
    with pytest.raises(ValueError) as refused:
        load_runtime_config(None, ["tau_s=0.5"])
    assert "e.g. alerts.tau_s=0.5" in str(refused.value) and "train." not in str(refused.value)


def test_the_schema_and_the_reference_page_are_the_ones_the_settings_make():
    import json

    from bsn_edge.runtime.config_schema import SCHEMA_FILE, reference_page, schema
    assert json.loads(SCHEMA_FILE.read_text()) == schema(), "regenerate: configs/runtime.schema.json"
    assert (CHECKOUT / "configs" / "runtime.schema.json").resolve() == SCHEMA_FILE.resolve()
    assert (CHECKOUT / "docs" / "settings.md").read_text() == reference_page(), "regenerate: docs/settings.md"


def test_the_shipped_file_lists_and_describes_every_key_the_schema_has():
    from bsn_edge.runtime.config_schema import comments, schema

    said = comments()

    def leaves(node, name):
        for key, v in node["properties"].items():
            if v["type"] == "object":
                yield from leaves(v, f"{name}.{key}")
            else:
                yield f"{name}.{key}", name

    every = [x for name, node in schema()["properties"].items() for x in leaves(node, name)]
    # runtime 7, sectors 3, alerts 1 + 4 + 4, health 3, bus 8, messages 2, source 4, calibration 2, visibility 16
    assert len(every) == 54
    for dotted, table in every:
        assert dotted in said, f"{dotted} is not in the shipped file"
        assert said[dotted] or said.get(table), f"{dotted} has no comment, nor has its table"


def test_a_second_reader_holds_the_shipped_file_to_the_schema_and_refuses_what_the_loader_refuses():
    """jsonschema (not the project's loader) validates the shipped file, and refuses a value out of range,
    a string for a number and a misspelt key, as the loader does."""
    import json
    import tomllib

    import jsonschema

    from bsn_edge.runtime.config_file import DEFAULTS_FILE
    from bsn_edge.runtime.config_schema import SCHEMA_FILE
    schema = json.loads(SCHEMA_FILE.read_text())
    shipped = tomllib.loads(DEFAULTS_FILE.read_text())
    jsonschema.validate(shipped, schema)
    for bad, key in ((("alerts", "tau_s"), 5.0), (("health", "deadline_s"), "0.5"), (("alerts", "tau"), 0.3)):
        wrong = tomllib.loads(DEFAULTS_FILE.read_text())
        wrong[bad[0]][bad[1]] = key
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(wrong, schema)
        with pytest.raises(ValueError):
            load_runtime_config(overrides=[f"{bad[0]}.{bad[1]}={key!r}" if isinstance(key, str)
                                           else f"{bad[0]}.{bad[1]}={key}"])


@pytest.mark.parametrize(("override", "says"), [
    ("alerts.tau=0.2", "'tau' (did you mean 'tau_s'?)"),
    ("sector.range_m=20", "'sector' (did you mean 'sectors'?)"),
    ("alerts.caution.delay=1", "'delay' (did you mean 'delay_s'?)"),
    ("runtime.cycle=0.2", "'cycle' (did you mean 'cycle_s'?)"),
])
def test_a_misspelt_key_is_answered_with_the_nearest_one(override, says):
    with pytest.raises(ValueError) as refused:
        load_runtime_config(overrides=[override])
    assert says in str(refused.value)


def test_a_vehicle_file_sets_each_messages_rate_as_heard_on_the_bus(setup, tmp_path):
    """[messages] status_every = 4: on the wire (decoded with cantools from the DBC, not the project's
    decoder), four hazard frames go out for each status frame, the status on every fourth cycle from the
    first, and the last word (UNAVAILABLE) carries both."""
    model, clip = setup
    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text("[bus]\ncan = \"virtual:bsn-rates\"\n\n[messages]\nhazard_every = 1\nstatus_every = 4\n")
    db = cantools.database.load_file(str(DBC_PATH))
    with can.Bus(interface="virtual", channel="bsn-rates") as rx:
        assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                             str(clip / "calibration.json"), "--config", str(vehicle)]) == 0
        names = [db.get_message_by_frame_id(m.arbitration_id).name for m in iter(lambda: rx.recv(0.2), None)]
    assert names[-2:] == ["BSN_Hazard", "BSN_Status"]          # the last word: every message
    cycles = names[:-2]
    assert cycles.count("BSN_Hazard") >= 12
    status_at = [i for i, n in enumerate(cycles) if n == "BSN_Status"]
    hazards_before = [sum(n == "BSN_Hazard" for n in cycles[:i]) for i in status_at]
    assert hazards_before == [1 + 4 * k for k in range(len(status_at))], hazards_before


def test_a_vehicle_file_sets_the_serial_baud_rate_and_the_frames_come_through(tmp_path):
    """[bus] serial on pyserial's loop (what is written is read back) at 57600 baud: the port is opened at
    that rate, and a cycle's bytes read back from it decode as both messages."""
    import argparse

    from bsn_edge.alerts import AlertFrame
    from bsn_edge.alerts.serial_codec import FrameDecoder

    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text("[bus]\nserial = \"loop://\"\nserial_baud = 57600\n")
    cfg = load_runtime_config(vehicle)
    args = argparse.Namespace(can=None, can_log=None, serial=None)
    (sender,) = run_cli.make_senders(args, cfg.bus)
    try:
        assert sender.port.baudrate == 57600
        assert sender.send(AlertFrame.unavailable(0.0))
        db = cantools.database.load_file(str(DBC_PATH))
        got = [db.get_message_by_frame_id(fid).name for fid, _ in FrameDecoder().feed(sender.port.read(256))]
        assert got == ["BSN_Hazard", "BSN_Status"]
    finally:
        sender.close()


def test_the_vehicle_files_threads_source_and_calibration_reach_what_they_set_and_flags_override_them(
        setup, tmp_path, monkeypatch):
    """runtime.threads and spin reach onnxruntime's session, [calibration] the camera's online estimator,
    [source] the reconnect policy a camera is opened with; --threads, --no-spin and --stall override the file."""
    from bsn_edge.runtime import live_source, sources

    model, clip = setup
    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text("[runtime]\nthreads = 1\nspin = true\n[source]\nstall_s = 3.5\nreconnect_first_s = 0.5\n"
                       "reconnect_max_s = 8.0\ngive_up_s = 20.0\n[calibration]\nframes_per_s = 5.0\nnice = 15\n")
    argv = ["--model", str(model), "--source", str(clip / "rgb"), "--config", str(vehicle)]
    cfg = run_cli.runtime_settings(run_cli.build_parser().parse_args(argv))
    engine, camera, source, _ = run_cli._start(run_cli.build_parser().parse_args(argv), cfg)
    try:
        options = engine.sess.get_session_options()
        assert options.intra_op_num_threads == 1
        try:
            spinning = options.get_session_config_entry("session.intra_op.allow_spinning") != "0"
        except Exception:      # no entry: onnxruntime's default, which spins
            spinning = True
        assert spinning
        assert camera.calibrate_hz == 5.0 and camera.calibrate_nice == 15
    finally:
        source.close()
        camera.close()
    assert cfg.source.reconnect() == live_source.Reconnect(3.5, 0.5, 8.0, 20.0)
    monkeypatch.setattr(live_source, "LiveSource", lambda target, policy: (target, policy))
    assert sources.open_source("0", reconnect=cfg.source.reconnect()) == (0, live_source.Reconnect(3.5, 0.5, 8.0, 20.0))
    flags = run_cli.runtime_settings(run_cli.build_parser().parse_args(
        [*argv, "--threads", "2", "--no-spin", "--stall", "1.5"]))
    assert (flags.threads, flags.spin, flags.source.stall_s) == (2, False, 1.5)
    with pytest.raises(ValueError, match="reconnect_first_s"):
        load_runtime_config(None, ["source.reconnect_first_s=9", "source.reconnect_max_s=1"])


def test_each_range_is_written_once_where_the_setting_is_declared_and_print_config_shows_it(capsys):
    """The shipped file carries no range of its own (a hand copy drifts); ``--print-config`` writes each key's
    range beside it from the setting's declaration, and what it prints is still the defaults."""
    import re
    import tomllib

    from bsn_edge.runtime.config_file import DEFAULTS_FILE
    from bsn_edge.runtime.config_schema import schema

    plain = re.compile(r"\(-?[\d.]+ to -?[\d.]+( [\w/]+)?\)")
    copied = [ln for ln in DEFAULTS_FILE.read_text().splitlines() if "#" in ln and plain.search(ln.split("#", 1)[1])]
    assert not copied, copied
    with pytest.raises(SystemExit):
        run_cli.main(["--print-config"])
    printed = capsys.readouterr().out
    assert tomllib.loads(printed) == tomllib.loads(DEFAULTS_FILE.read_text())

    def ranged(node, name):
        for key, v in node["properties"].items():
            if v["type"] == "object":
                yield from ranged(v, f"{name}.{key}")
            elif "minimum" in v:
                yield name, key, v

    lines = printed.splitlines()
    for table, key, v in (x for name, node in schema()["properties"].items() for x in ranged(node, name)):
        start = lines.index(f"[{table}]") if f"[{table}]" in lines else \
            next(i for i, ln in enumerate(lines) if ln.startswith(f"[{table}]"))
        line = next(ln for ln in lines[start + 1:] if re.match(rf"{key}\s*=", ln))
        assert f"({v['minimum']:g} to " in line or "to 4_000_000" in line, line


def test_one_command_regenerates_what_the_settings_make_and_its_check_names_a_stale_file(tmp_path, capsys):
    import shutil

    from bsn_edge.runtime import config_schema

    assert config_schema.main(["--check"], CHECKOUT) == 0, "the checkout's generated files are the settings' own"
    (tmp_path / "docs").mkdir()
    for name in ("settings.md", "runtime.md"):
        shutil.copy(CHECKOUT / "docs" / name, tmp_path / "docs" / name)
    (tmp_path / "docs" / "settings.md").write_text("# stale\n")
    assert config_schema.main(["--check"], tmp_path) == 1 and "settings.md: stale" in capsys.readouterr().out
    assert config_schema.main([], tmp_path) == 0 and config_schema.main(["--check"], tmp_path) == 0, \
        "written, then not stale"
