"""The alert state machine over scripted timestamps."""

import pytest

from bsn_edge.alerts import AlertConfig, Level, LevelRule, SectorState
from bsn_edge.alerts.health import Health, HealthConfig, SystemState

FAST = AlertConfig(tau_s=0.0, caution=LevelRule(0.3, 0.2, delay_s=0.5, hold_s=1.0),
                   warning=LevelRule(0.7, 0.5, delay_s=0.2, hold_s=2.0))


def run(score_at, t_end, dt=0.05, cfg=FAST):
    m = SectorState(cfg)
    out = []
    t = 0.0
    while t <= t_end + 1e-9:
        out.append((round(t, 3), *m.update(t, score_at(t))))
        t += dt
    return out


def level_at(trace, t):
    return next(lv for tt, _, lv in trace if tt >= t - 1e-9)


def test_creation_delay_debounces_a_blip():
    trace = run(lambda t: 0.5 if 1.0 <= t < 1.3 else 0.0, 3.0)   # 0.3 s above 'on', delay 0.5 s
    assert all(lv == Level.NONE for _, _, lv in trace)
    trace = run(lambda t: 0.5 if t >= 1.0 else 0.0, 3.0)
    assert level_at(trace, 1.45) == Level.NONE and level_at(trace, 1.5) == Level.CAUTION


def test_minimum_hold_keeps_a_level_after_the_score_drops():
    trace = run(lambda t: 0.5 if 1.0 <= t < 2.0 else 0.0, 5.0)   # CAUTION from 1.5
    assert level_at(trace, 2.05) == Level.CAUTION                 # score gone, but held
    assert level_at(trace, 2.45) == Level.CAUTION
    assert level_at(trace, 2.5) == Level.NONE                     # 1.0 s after it began


def test_hysteresis_between_on_and_off():
    # rises above on (0.3), then sits between off (0.2) and on: stays CAUTION indefinitely
    trace = run(lambda t: 0.35 if t < 2.0 else 0.25, 10.0)
    assert level_at(trace, 9.9) == Level.CAUTION
    trace = run(lambda t: 0.35 if t < 2.0 else 0.15, 10.0)
    assert level_at(trace, 9.9) == Level.NONE


def test_warning_escalates_and_steps_down_through_caution():
    def score(t):
        return 0.9 if 1.0 <= t < 2.0 else (0.25 if t < 6.0 else 0.0)
    trace = run(score, 10.0)
    assert level_at(trace, 1.2) == Level.WARNING      # WARNING's own 0.2 s delay, straight from NONE
    assert level_at(trace, 3.1) == Level.WARNING      # held 2 s from 1.2
    assert level_at(trace, 3.3) == Level.CAUTION      # 0.25 is under WARNING's off but over CAUTION's
    assert level_at(trace, 6.0) == Level.CAUTION
    assert level_at(trace, 6.1) == Level.NONE


def test_smoothing_depends_on_time_not_frame_rate():
    cfg = AlertConfig(tau_s=0.5)
    for dt in (0.02, 0.1):
        m = SectorState(cfg)
        m.update(0.0, 0.0)
        t = 0.0
        while t < 0.5 - 1e-9:
            t += dt
            s, _ = m.update(t, 1.0)
        assert s == pytest.approx(1 - 2.718281828 ** -1, abs=1e-6)


def test_time_must_not_go_backwards():
    m = SectorState(FAST)
    m.update(1.0, 0.0)
    with pytest.raises(ValueError, match="backwards"):
        m.update(0.5, 0.0)


def test_config_is_validated():
    with pytest.raises(ValueError):
        LevelRule(on=0.2, off=0.3, delay_s=0, hold_s=0)
    with pytest.raises(ValueError, match="WARNING"):
        AlertConfig(caution=LevelRule(0.5, 0.4, 0, 0), warning=LevelRule(0.4, 0.3, 0, 0))


def test_health_unavailable_after_deadline_and_degraded_when_slow():
    h = Health(HealthConfig(deadline_s=0.5, fps_floor=8.0, window_s=1.0))
    assert h.state(0.0) == SystemState.UNAVAILABLE
    for k in range(30):
        h.valid(k * 0.05)                      # 20 fps
    assert h.state(1.5) == SystemState.OK
    assert h.state(2.0) == SystemState.UNAVAILABLE   # nothing for 0.55 s
    for k in range(10):
        h.valid(3.0 + k * 0.2)                 # 5 fps
    assert h.state(4.9) == SystemState.DEGRADED
    h.fault("nan_outputs")
    assert h.faults["nan_outputs"] == 1
    with pytest.raises(KeyError):
        h.fault("gremlins")


def test_the_first_inference_is_on_time_until_the_floor_says_otherwise():
    """One inference alone says nothing of the rate until 1 / fps_floor has passed without a second."""
    h = Health(HealthConfig(deadline_s=0.5, fps_floor=8.0, window_s=1.0))
    h.valid(10.0)
    assert h.state(10.0) == SystemState.OK and h.state(10.1) == SystemState.OK
    assert h.state(10.2) == SystemState.DEGRADED          # no second inference in 0.2 s: under 8 per second
    h.valid(10.21)
    assert h.state(10.21) == SystemState.DEGRADED         # two in 0.21 s: still under 8 per second


def test_a_fault_outranks_calibrating():
    """UNAVAILABLE > DEGRADED > CALIBRATING > OK: a slow loop or a failed output while the camera is
    still being calibrated reads DEGRADED, not CALIBRATING."""
    h = Health(HealthConfig(deadline_s=0.5, fps_floor=8.0, window_s=1.0))
    h.calibrating(True)
    for k in range(30):
        h.valid(k * 0.05)                      # 20 fps
    assert h.state(1.45) == SystemState.CALIBRATING
    for k in range(10):
        h.valid(2.0 + k * 0.2)                 # 5 fps
    assert h.state(3.85) == SystemState.DEGRADED
    h2 = Health(HealthConfig(deadline_s=0.5, fps_floor=8.0, window_s=1.0))
    h2.calibrating(True)
    for k in range(30):
        h2.valid(k * 0.05)
    h2.fault("sink_errors")
    assert h2.state(1.45) == SystemState.DEGRADED
    assert h2.state(3.0) == SystemState.UNAVAILABLE
