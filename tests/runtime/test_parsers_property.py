"""Every file the product parses, fed what an attacker or a damaged disk gives: deep nesting, numbers of
hundreds of digits, the wrong types where tables belong. Each parser answers with its own error type (a
ValueError naming the file), never a crash of another kind; hypothesis draws the inputs."""

from __future__ import annotations

import contextlib
import json
import string

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bsn_edge.alerts.can_log import read_log
from bsn_edge.calibration import Calibration
from bsn_edge.runtime.config_file import load_runtime_config

HUGE = st.integers(min_value=10 ** 30, max_value=10 ** 400) | st.integers(max_value=-(10 ** 30), min_value=-(10 ** 400))
LEAF = st.none() | st.booleans() | st.floats(allow_nan=True, allow_infinity=True) | st.integers() | HUGE | \
    st.text(string.printable, max_size=12)
VALUES = st.recursive(LEAF, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                        max_size=4), max_leaves=20)
DEPTH = st.integers(min_value=1, max_value=6000)
SECTIONS = ("runtime", "sectors", "alerts", "health", "bus", "messages", "source", "calibration", "visibility")
KEYS = ("cycle_s", "warmup", "range_m", "layout", "on", "deadline_s", "can", "stall_s", "frozen_s", "caution",
        "outputs")
FAST = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _toml_value(v) -> str:
    """A TOML spelling of a drawn value (None and non-finite floats as strings TOML takes)."""
    if v is None:
        return '"none"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if v == v and abs(v) != float("inf") else '"nan"'
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"


@FAST
@given(section=st.sampled_from(SECTIONS), key=st.sampled_from(KEYS), value=VALUES, depth=DEPTH,
       shape=st.sampled_from(["value", "array", "inline", "table-array", "section-value"]))
def test_any_vehicle_file_is_read_or_refused_as_invalid_input(tmp_path_factory, section, key, value, depth, shape):
    path = tmp_path_factory.mktemp("vehicle") / "v.toml"
    text = {"value": f"[{section}]\n{key} = {_toml_value(value)}\n",
            "array": f"[{section}]\n{key} = {'[' * depth}1{']' * depth}\n",
            "inline": f"[{section}]\n{key} = {'{a = ' * depth}1{'}' * depth}\n",
            "table-array": f"[[{section}]]\n{key} = {_toml_value(value)}\n",
            "section-value": f"{section} = {_toml_value(value)}\n"}[shape]
    path.write_text(text)
    try:
        load_runtime_config(path)
    except ValueError as e:
        assert len(str(e)) < 2000, "a message that prints the whole input"


@FAST
@given(over=st.sampled_from([f"{s}.{k}" for s in SECTIONS for k in KEYS]), value=VALUES | HUGE, depth=DEPTH)
def test_any_set_is_read_or_refused_as_invalid_input(over, value, depth):
    for raw in (_toml_value(value), "[" * depth + "]" * depth):
        with contextlib.suppress(ValueError):
            load_runtime_config(None, [f"{over}={raw}"])


@FAST
@given(field=st.sampled_from(["fx", "fy", "cx", "cy", "width", "height", "dist", "mounting", "hood", "used"]),
       value=VALUES | HUGE, depth=DEPTH, nest=st.booleans())
def test_any_camera_file_is_read_or_refused_as_invalid_input(tmp_path_factory, field, value, depth, nest):
    good = {"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 180.0, "width": 640, "height": 360, "dist": [0, 0, 0, 0, 0]}
    path = tmp_path_factory.mktemp("camera") / "c.json"
    path.write_text("[" * depth + "]" * depth if nest else json.dumps({**good, field: value}))
    try:
        Calibration.read(path)
    except ValueError as e:
        assert str(path) in str(e)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(line=VALUES, depth=DEPTH, nest=st.booleans(),
       summary=VALUES | st.dictionaries(st.sampled_from(["model", "camera", "source", "machine", "settings_digest",
                                                         "visibility", "states_s"]), VALUES, max_size=4),
       field=st.sampled_from(["frame", "t", "levels", "scores", "distances", "state", "bus_from", "latency_ms",
                              "stage_ms", "camera", "unseen", "fault"]),
       value=VALUES | st.just(1e400) | st.just(-1e400))
def test_any_frame_log_and_summary_make_a_report_or_are_refused_as_invalid(tmp_path_factory, line, depth, nest,
                                                                          summary, field, value):
    """A damaged line is counted and the drive read on (a field of a good line given any value included); a
    summary of the wrong shape is refused by name."""
    from bsn_edge.report import make_report, read_drive

    folder = tmp_path_factory.mktemp("report")
    good = json.dumps({"frame": 0, "t": 0.0, "levels": ["NONE"] * 3, "scores": [0.0] * 3,
                       "distances": [None] * 3, "state": "OK"})
    log = folder / "log.jsonl"
    odd = json.dumps({**json.loads(good), field: value})
    log.write_text(good + "\n" + ("[" * depth + "]" * depth if nest else json.dumps(line)) + "\n" + good + "\n"
                   + odd + "\n")
    drive = read_drive(log)
    assert len(drive.records) >= 2
    summ = folder / "s.json"
    summ.write_text(json.dumps(summary if not isinstance(summary, dict) else {"frames": 2, **summary}))
    try:
        make_report(log, folder / "r", summary=summ, say=lambda s: None)
    except ValueError as e:
        assert str(summ) in str(e)


@FAST
@given(data=st.binary(max_size=4000), nul=st.integers(0, 3000))
def test_any_can_log_is_read_frame_by_frame_and_its_damage_counted(tmp_path_factory, data, nul):
    folder = tmp_path_factory.mktemp("canlog")
    good = "(1.000000) vcan0 500#0011223344556677\n"
    for name, body in (("a.log", good.encode() + b"\0" * nul + data + b"\n" + good.encode()), ("b.blf", data)):
        (folder / name).write_bytes(body)
        bad: list[str] = []
        frames = list(read_log(folder / name, lambda where, why, bad=bad: bad.append(why)))
        if name == "a.log":
            assert len(frames) >= 2 and frames[0].data == bytes.fromhex("0011223344556677")
