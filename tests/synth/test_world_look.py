"""The realistic world: vehicles and people from parts, cast shadows, sensor effects, new styles."""

import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.synth import SynthConfig, make_clip
from bsn_edge.synth.boxes import KIND_CABIN, KIND_WHEEL, Boxes
from bsn_edge.synth.light import GroundMaps
from bsn_edge.synth.people import person_parts
from bsn_edge.synth.sensor import Sensor, SensorModel
from bsn_edge.synth.vehicles import TYPES, Placed, draw_size, vehicle_parts


@pytest.mark.parametrize("name", sorted(TYPES))
def test_vehicle_parts_stay_inside_the_drawn_size_and_share_one_track(name):
    rng = np.random.default_rng(1)
    vt = TYPES[name]
    size = draw_size(rng, vt)
    b = vehicle_parts(rng, vt, Placed(1, 10.0, -5.0, -1.0), size, track=7)
    assert np.all(b.track == 7)
    length, width, height = size
    # a road along y: x is across, y along
    assert b.lo[:, 0].min() >= 10.0 - width / 2 - 1e-9 and b.hi[:, 0].max() <= 10.0 + width / 2 + 1e-9
    assert b.lo[:, 1].min() >= -5.0 - length / 2 - 1e-9 and b.hi[:, 1].max() <= -5.0 + length / 2 + 1e-9
    assert b.lo[:, 2].min() == 0.0
    if not vt.two_wheeler:
        assert (b.kind == KIND_WHEEL).sum() >= 2 and np.all(b.cls == vt.cls)
        assert abs(b.hi[:, 2].max() - height) < 1e-9
    if name in ("car", "suv", "hatchback", "van"):
        assert (b.kind == KIND_CABIN).sum() == 1
    assert np.all(b.facing == -2)    # front towards -y


def test_person_has_two_legs_a_torso_and_a_head():
    b = person_parts(np.random.default_rng(3), Placed(0, 2.0, 4.0, 1.0), track=2)
    assert len(b) >= 4 and np.all(b.cls == sm.PERSON) and np.all(b.track == 2)
    assert 1.0 < b.hi[:, 2].max() < 2.0


def test_cast_shadow_falls_where_the_sun_ray_says():
    # a 2 x 2 x 4 m box, the sun 45 degrees up towards +x: the shadow reaches 4 m towards -x
    box = Boxes.make([(0.0, 0.0, 0.0)], [(2.0, 2.0, 4.0)], sm.BUILDING, 0, (0.5, 0.5, 0.5))
    s = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    maps = GroundMaps(tuple(s), night=False)
    maps.update(box, Boxes.empty(), np.array([0.0, 0.0]))
    x = np.array([-1.0, -3.5, -4.6, 3.0, 1.0, 2.15], np.float32)
    y = np.array([1.0, 1.0, 1.0, 1.0, 3.0, 1.0], np.float32)
    lit, ao, lamp = maps.ground_light(x, y)
    np.testing.assert_allclose(lit[:5], [0.0, 0.0, 1.0, 1.0, 1.0], atol=0.01)
    assert ao[5] > 0.4 and ao[3] == 0 and lamp is None    # contact shadow hugs the footprint
    # a point on another object, 1 m up at x = -2, is shaded; 3.5 m up at x = -0.3 it is not
    other = np.array([99], np.int32)
    assert maps.object_lit(np.float32([-2.0]), np.float32([1.0]), np.float32([1.0]), other)[0] == 0.0
    assert maps.object_lit(np.float32([-0.6]), np.float32([1.0]), np.float32([3.9]), other)[0] == 1.0


def test_sensor_defaults_are_plain_8_bit_and_effects_keep_the_focus_of_expansion():
    rng = np.random.default_rng(0)
    rad = rng.uniform(0, 1, (32, 48, 3)).astype(np.float32)
    plain = SensorModel(Sensor(), 48, 32, (24, 16), 40.0).develop(rad)
    np.testing.assert_array_equal(plain, np.clip(rad * 255 + 0.5, 0, 255).astype(np.uint8))
    # zoom blur: the pixel at the focus of expansion does not move; the edges smear
    img = np.zeros((32, 48, 3), np.float32)
    img[16, 24] = 1.0
    img[:, 40] = 1.0
    blur = SensorModel(Sensor(shutter_s=0.05), 48, 32, (24, 16), 40.0).develop(img, speed_mps=20.0)
    assert blur[16, 24, 0] == 255
    assert blur[:, 41:44, 0].max() > 0
    with pytest.raises(ValueError, match="jpeg_quality"):
        Sensor(jpeg_quality=3)


@pytest.mark.parametrize("style", ["highway", "urban"])
def test_new_styles_render_their_character(style):
    clip = make_clip(SynthConfig(frames=20, height=64, width=128, style=style, seed=2))
    w = clip.scenario.world
    kinds = np.concatenate([w.static.cls, w.agents.boxes.cls])
    if style == "highway":
        assert w.layout.verge and (w.static.cls == sm.WALL).any()          # barriers
        assert not np.isin(kinds, (sm.BICYCLE, sm.PERSON)).any()
    else:
        n_people = len(np.unique(w.agents.boxes.track[w.agents.boxes.cls == sm.PERSON]))
        assert n_people > 50
