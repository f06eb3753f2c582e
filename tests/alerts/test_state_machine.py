"""The alert state machine over scripted timestamps."""

import math

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


def test_each_state_says_why_in_the_status():
    """The same timeline as above, read as the status's ``why``: none for OK, the first reason otherwise (what
    the end lines and the report sum per state)."""
    from bsn_edge.alerts.blindness import Blindness

    h = Health(HealthConfig(deadline_s=0.5, fps_floor=8.0, window_s=1.0))
    assert h.snapshot(0.0).why == "no valid inference yet"
    h.calibrating(True)
    for k in range(30):
        h.valid(k * 0.05)
    assert h.snapshot(1.45).why == "calibrating: levels from an assumed camera"
    h.calibrating(False)
    assert h.snapshot(1.45).why == "" and h.snapshot(1.45).state == SystemState.OK
    assert h.snapshot(2.0).why.startswith("stall")
    for k in range(10):
        h.valid(3.0 + k * 0.2)
    assert h.snapshot(4.9).why == "frame rate under health.fps_floor"
    h.camera(Blindness.COVERED)
    assert (h.snapshot(4.9).state, h.snapshot(4.9).why) == (SystemState.UNAVAILABLE, "camera COVERED")
    h.camera(Blindness.CLEAR)
    h.sender_down("can", True)
    assert h.snapshot(4.85).why in ("frame rate under health.fps_floor", "output down: can")
    h.unavailable()
    assert h.snapshot(4.9).why == "the run ending"


# A step of the raw score and the times the levels must change, worked out from the exponential
# s(t) = 1 - exp(-(t - t0) / tau) (rising) and s(t) = s0 exp(-(t - t0) / tau) (falling), not from the
# machine. The machine holds each sample's score over the interval before it (zero-order hold), so a
# step first seen at sample t acts from the sample before: t0 = t - dt.
SMOOTH = AlertConfig(tau_s=0.5, caution=LevelRule(0.25, 0.15, delay_s=0.2, hold_s=1.0),
                     warning=LevelRule(0.6, 0.45, delay_s=0.1, hold_s=1.5))
DT = 0.01


def _first_sample_at_or_after(t: float) -> float:
    return math.ceil(t / DT - 1e-9) * DT


def test_levels_follow_the_smoothed_score_at_the_times_the_exponential_gives():
    tau, rise0, fall0 = SMOOTH.tau_s, 1.0 - DT, 3.0 - DT
    trace = run(lambda t: 1.0 if 1.0 - 1e-9 <= t < 3.0 - 1e-9 else 0.0, 6.0, dt=DT, cfg=SMOOTH)
    crosses = {lv: _first_sample_at_or_after(rise0 + tau * math.log(1 / (1 - rule.on)))
               for lv, rule in ((Level.CAUTION, SMOOTH.caution), (Level.WARNING, SMOOTH.warning))}
    caution_at = _first_sample_at_or_after(crosses[Level.CAUTION] + SMOOTH.caution.delay_s)
    warning_at = _first_sample_at_or_after(crosses[Level.WARNING] + SMOOTH.warning.delay_s)
    # on the raw score CAUTION would come at 1.2 s and WARNING at 1.1 s
    assert caution_at == pytest.approx(1.34) and warning_at == pytest.approx(1.55)
    assert level_at(trace, caution_at - DT) == Level.NONE
    assert level_at(trace, caution_at) == Level.CAUTION
    assert level_at(trace, warning_at - DT) == Level.CAUTION
    assert level_at(trace, warning_at) == Level.WARNING
    # the fall: from s0 the smoothed score passes WARNING's off (its hold long over), the machine steps
    # to CAUTION there and holds it a second from then, though the score passes CAUTION's off before
    s0 = 1 - math.exp(-(fall0 - rise0) / tau)
    warning_off = _first_sample_at_or_after(fall0 + tau * math.log(s0 / SMOOTH.warning.off))
    caution_off = _first_sample_at_or_after(fall0 + tau * math.log(s0 / SMOOTH.caution.off))
    assert warning_off - warning_at > SMOOTH.warning.hold_s and caution_off < warning_off + SMOOTH.caution.hold_s
    none_at = _first_sample_at_or_after(warning_off + SMOOTH.caution.hold_s)
    assert level_at(trace, warning_off - DT) == Level.WARNING
    assert level_at(trace, warning_off) == Level.CAUTION
    assert level_at(trace, none_at - DT) == Level.CAUTION
    assert level_at(trace, none_at) == Level.NONE
    for t, s, _ in trace:   # and the score the bus carries is that exponential
        want = 0.0 if t < 1.0 else (1 - math.exp(-(min(t, fall0) - rise0) / tau)) * math.exp(-max(t - fall0, 0) / tau)
        assert s == pytest.approx(want, abs=1e-9), t


def test_a_one_frame_spike_is_smoothed_away_even_with_no_creation_delay():
    """30 frames a second, one frame at score 1: smoothed it is 1 - exp(-1/30 / 0.3) = 0.105, under
    CAUTION's 0.25, so no level, however short the delay."""
    cfg = AlertConfig(tau_s=0.3, caution=LevelRule(0.25, 0.15, delay_s=0.0, hold_s=1.0),
                      warning=LevelRule(0.6, 0.45, delay_s=0.0, hold_s=1.5))
    m = SectorState(cfg)
    levels, peak = [], 0.0
    for k in range(60):
        s, lv = m.update(k / 30, 1.0 if k == 30 else 0.0)
        levels.append(lv)
        peak = max(peak, s)
    assert peak == pytest.approx(1 - math.exp(-1 / 30 / 0.3), abs=1e-9)
    assert set(levels) == {Level.NONE}


def test_a_warning_whose_score_is_gone_ends_at_its_hold_straight_to_none():
    """0.9 from 1 s to 2 s, then 0 (no smoothing): WARNING from 1.2 s (its 0.2 s delay), held 2 s to
    3.2 s; the score is then under CAUTION's off too, so the level goes to NONE at once. A CAUTION in
    between would linger its own hold (1 s) with nothing on the road."""
    trace = run(lambda t: 0.9 if 1.0 - 1e-9 <= t < 2.0 - 1e-9 else 0.0, 6.0)
    assert level_at(trace, 3.15) == Level.WARNING
    assert level_at(trace, 3.2) == Level.NONE
    assert Level.CAUTION not in {lv for t, _, lv in trace if t >= 1.2}
