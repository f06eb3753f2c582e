"""Property, over whole runs: no setting and no camera file can silence the alerts.

Random settings (every runtime key, drawn over its whole range and a little beyond it) and random camera
files (field of view, lens, mounting and hood, drawn over what real cameras have and a little beyond) are
either refused before the first frame, or a run of 12 s of video in which the model sees a near occluder
wherever the camera looks raises a level on the bus. The model is the test's: the exported graph's
answer replaced by that occluder (1 m away in the model camera, over the whole frame), so what is judged is everything
around it: settings, camera, warp, hood, sectors, smoothing, state and send cycle.
"""

import dataclasses
import json
import math

import numpy as np
import pytest

from bsn_edge.alerts import Level, SystemState
from bsn_edge.alerts.can_codec import HAZARD, STATUS, decode
from bsn_edge.alerts.senders import Sender
from bsn_edge.calibration import Calibration
from bsn_edge.runtime import Engine, RuntimeConfig, open_source, run
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.config_file import load_runtime_config
from tests.fakes import long_video

OCCLUDER_M = 1.0     # metres in the model camera: 3.3 m from the highest camera a file may hold (5 m)
# derandomized, so CI runs the same examples every time; the slow-marked runs explore more (pytest -m slow)
EXAMPLES, THOROUGH = 12, 60
CAMERA_EXAMPLES, CAMERA_THOROUGH = 20, 120     # most random camera files are refused: more of them


class OccluderEngine(Engine):
    """The model's answer, once its self-test has passed: a blind spot over the whole frame, ``OCCLUDER_M``
    away."""

    occluding = False

    def infer(self, batch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        prob, depth = super().infer(batch)
        if not self.occluding:
            return prob, depth
        return np.ones_like(prob), np.full_like(depth, OCCLUDER_M)


class Heard(Sender):
    """The levels and states that went out, decoded from the bus's own bytes."""

    name = "heard"

    def __init__(self) -> None:
        super().__init__()
        self.levels: list[int] = []
        self.states: list[int] = []

    def _send(self, frames):
        for i, d in frames:
            m = decode(i, d)
            if m.name == HAZARD:
                self.levels.append(max(int(m.signals[f"{s}_Level"]) for s in ("Left", "Centre", "Right")))
            elif m.name == STATUS:
                self.states.append(int(m.signals["System_State"]))


def _ranged(cls, prefix=""):
    """(dotted key, low, high, kind) of every ranged setting of the dataclass ``cls``, nested ones too (the
    top level's own keys are the file's ``[runtime]`` table)."""
    out = []
    own = prefix or "runtime."
    for f in dataclasses.fields(cls):
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        if dataclasses.is_dataclass(default):
            out += _ranged(type(default), f"{prefix}{f.name}.")
        elif "range" in f.metadata:
            lo, hi = f.metadata["range"]
            out.append((f"{own}{f.name}", lo, hi, type(default)))
        elif isinstance(default, bool):
            out.append((f"{own}{f.name}", False, True, bool))
    return out


def _settings():
    from hypothesis import strategies as st

    def value(lo, hi, kind):
        if kind is bool:
            return st.booleans()
        if kind is int:
            return st.integers(int(lo), int(hi))
        span = hi - lo
        inside = st.one_of(st.sampled_from([lo, hi]), st.floats(lo, hi))
        return st.one_of(inside, inside, inside, st.floats(lo - 0.1 * span, hi + 0.1 * span))

    keys = _ranged(RuntimeConfig)
    return st.lists(st.sampled_from(keys).flatmap(lambda k: st.tuples(st.just(k[0]), value(*k[1:]))),
                    max_size=6)


def _camera():
    from hypothesis import strategies as st

    lens = st.sampled_from([[], [], [-0.24, 0.05, 0.001, -0.0005, 0.0], [-0.45, 0.2, 0.0, 0.0, -0.03],
                            [0.15, 0.0, 0.0, 0.0, 0.0], [-0.3, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0],
                            [0.0, 0.0, 0.2, 0.0, 0.0], [-0.9, 0.0, 0.0, 0.0, 0.0], [0.0] * 8 + [5.0, 0.0, 0.0, 0.0]])
    def mostly(lo, hi, beyond):
        """Within a real camera's range six times in seven, a little beyond it the seventh."""
        return st.one_of(*[st.floats(lo, hi)] * 6, st.floats(lo - beyond, hi + beyond))

    angle = st.one_of(*[st.floats(-8.0, 8.0)] * 3, mostly(-30.0, 30.0, 5.0))     # dashcams, then anything
    height = st.one_of(*[st.sampled_from([1.1, 1.3, 1.5, 1.8, 2.4, 3.2])] * 3, mostly(0.2, 5.0, 0.5))
    mounting = st.fixed_dictionaries({"height_m": height, "pitch_deg": angle, "yaw_deg": angle, "roll_deg": angle})
    # the hood's outline row as a share of the height, x^2, x and constant terms (np.polyval's order)
    arch = st.tuples(st.floats(-0.1, 0.1), st.floats(-0.05, 0.05), mostly(0.65, 1.0, 0.3)).map(list)
    drawn = st.fixed_dictionaries({"share": mostly(0.0, 0.35, 0.2), "spread": st.just(0.0), "columns": st.just(1.0),
                                   "arch": arch, "frames": st.just(40)})
    hood = st.one_of(st.none(), st.none(), drawn)
    hfov = st.one_of(*[st.floats(50.0, 120.0)] * 4, st.floats(5.0, 175.0))     # dashcams, then anything
    return st.fixed_dictionaries({"hfov_deg": hfov, "dist": lens, "mounting": mounting,
                                  "hood": hood})


def _toml(v) -> str:
    return ("true" if v else "false") if isinstance(v, bool) else repr(v)


def _runs(setup, tmp_path):
    """(check: settings overrides and a camera file's dict -> "refused_settings" | "refused_camera" | "ran",
    asserting a level was raised when it ran; the tally)."""
    model, clip = setup
    video = long_video(clip, tmp_path / "long.mp4", 8)       # 120 frames at 10 frames/s
    engine = OccluderEngine(model)
    engine.occluding = True
    base = json.loads((clip / "calibration.json").read_text())
    tally = {"refused_settings": 0, "refused_camera": 0, "ran": 0}

    def check(pairs, cam):
        try:
            cfg = load_runtime_config(overrides=[f"{k}={_toml(v)}" for k, v in pairs])
        except ValueError:
            tally["refused_settings"] += 1
            return
        d = dict(base)
        if cam is not None:
            d.update(dist=cam["dist"], mounting=cam["mounting"])
            d["fx"] = d["fy"] = d["width"] / (2 * math.tan(math.radians(cam["hfov_deg"]) / 2))
            if cam["hood"] is not None:
                d["hood"] = cam["hood"]
        path = tmp_path / "camera.json"
        path.write_text(json.dumps(d))
        try:            # as bsn-run starts: the file read, then what its camera shows checked
            camera = CameraState(engine.card, Calibration.read(path))
            camera.check_view(d["width"], d["height"])
        except ValueError:
            tally["refused_camera"] += 1
            return
        heard = Heard()
        run(engine, open_source(str(video)), [heard], cfg, camera=camera)
        tally["ran"] += 1
        assert max(heard.levels) >= Level.CAUTION, (pairs, cam, "no level was raised")
        assert SystemState.OK in heard.states or SystemState.DEGRADED in heard.states, (pairs, cam)

    return check, tally


def _settings_property(setup, tmp_path, examples: int) -> None:
    from hypothesis import HealthCheck, given, settings

    check, tally = _runs(setup, tmp_path)
    given(_settings())(settings(max_examples=examples, deadline=None, derandomize=True,
                                suppress_health_check=[HealthCheck.function_scoped_fixture])(
        lambda pairs: check(pairs, None)))()
    print(tally)
    assert tally["ran"] >= examples // 3, tally


def _camera_property(setup, tmp_path, examples: int) -> None:
    from hypothesis import HealthCheck, given, settings

    check, tally = _runs(setup, tmp_path)
    given(_camera())(settings(max_examples=examples, deadline=None, derandomize=True,
                              suppress_health_check=[HealthCheck.function_scoped_fixture])(
        lambda cam: check([], cam)))()
    print(tally)
    assert tally["ran"] >= examples // 5, tally


def test_random_settings_are_refused_or_a_near_occluder_raises_a_level(setup, tmp_path):
    """Every runtime key drawn over its range (its ends included) and a little beyond, with the clip's own
    camera file."""
    _settings_property(setup, tmp_path, EXAMPLES)


def test_random_camera_files_are_refused_or_a_near_occluder_raises_a_level(setup, tmp_path):
    """Field of view, lens, mounting and hood drawn over what real cameras have and a little beyond, with
    the runtime's default settings."""
    _camera_property(setup, tmp_path, CAMERA_EXAMPLES)


@pytest.mark.slow
def test_many_random_settings_and_camera_files(setup, tmp_path):
    """The same properties over five times the examples (about 5 minutes)."""
    for name in ("settings", "camera"):
        (tmp_path / name).mkdir()
    _settings_property(setup, tmp_path / "settings", THOROUGH)
    _camera_property(setup, tmp_path / "camera", CAMERA_THOROUGH)
