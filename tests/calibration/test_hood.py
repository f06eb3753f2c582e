"""The car's own hood, found from a few seconds of driving: against the hood the renderer painted
(its share of the rows, its arch, its pixels), never on clips without one, not on real dashcams
without one; kept in the camera file; masked out of what the runtime reads."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.calibration.hood import Hood, HoodConfig, HoodFinder, find_hood
from bsn_edge.camera import Intrinsics
from bsn_edge.model_frame import ModelFrame, model_camera
from bsn_edge.mounting import Mounting
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.sequence.frames import read_rgb
from bsn_edge.sequence.media import read_video
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.synth.rig import Rig, hood_mask
from tests.cards import card_for

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"
HOODS = (0, 9, 30)              # rigs whose hood covers 11-15 % of the rows at the centre
BARE = (1, 5)                   # and rigs without one
FRAMES = 40                     # the first 4 s, as bsn-run looks (HoodConfig.frames)


def frames_of(clip: Path, n: int = FRAMES) -> list[np.ndarray]:
    return [read_rgb(clip, i) for i in range(n)]


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    root = tmp_path_factory.mktemp("hoods")
    return {s: write_clip(SynthConfig(frames=FRAMES, height=128, width=256, seed=s), root / f"rig{s}", video=False)
            for s in HOODS + BARE}


def test_the_painted_hood_is_found_with_its_share_arch_and_pixels(clips):
    for s in HOODS:
        truth = Rig.draw(s).hood
        assert truth > 0.1
        hood = find_hood(frames_of(clips[s]))
        assert hood.found and abs(hood.share - truth) < 0.01 + 3 * hood.spread, (s, hood, truth)
        # the renderer's arch: top row share 1 - hood (1 - 0.45 x^2)
        c, b, a = hood.arch
        assert abs(a - (1 - truth)) < 0.01 and abs(c - 0.45 * truth) < 0.015 and abs(b) < 0.01, (s, hood.arch)
        painted, found = hood_mask(256, 128, truth), hood.mask(256, 128)
        assert (painted & found).sum() / (painted | found).sum() > 0.9
        assert hood.columns > 0.6 and hood.spread < 0.01


def test_no_hood_is_found_where_there_is_none(clips):
    for s in BARE:
        assert Rig.draw(s).hood == 0
        hood = find_hood(frames_of(clips[s]))
        assert not hood.found and not hood.mask(256, 128).any() and hood.arch == ()


@pytest.mark.parametrize("name", ["dashcam_highway.mp4", "udacity_test_video.mp4"])
def test_real_dashcams_without_a_hood_report_none(name):
    if not (REAL / name).is_file():
        pytest.skip(f"real data absent: {REAL / name}")
    hood = find_hood(read_video(REAL / name, max_frames=40))
    assert not hood.found, hood


def test_too_few_frames_say_nothing_and_the_finder_keeps_only_what_it_needs(clips):
    frames = frames_of(clips[HOODS[0]])
    assert not find_hood(frames[:10]).found
    finder = HoodFinder(HoodConfig(frames=FRAMES - 2))
    for f in frames:
        finder.add(f)
    assert finder.ready and len(finder.frames) == FRAMES - 2 and finder.frames[0].dtype == np.float32
    assert finder.result() == find_hood(frames[:FRAMES - 2], HoodConfig(frames=FRAMES - 2))


def test_the_camera_file_keeps_the_hood_and_files_without_one_are_unchanged(tmp_path):
    cal = Calibration.of(Intrinsics.from_fov(256, 128, 80.0), (), Mounting(1.4, 2.0))
    cal.write(tmp_path / "old.json")
    assert "hood" not in json.loads((tmp_path / "old.json").read_text())
    assert Calibration.read(tmp_path / "old.json").hood is None
    hood = Hood(0.12, 0.002, 0.95, (0.054, 0.0, 0.88), 40)
    cal.with_hood(hood).write(tmp_path / "new.json")
    assert Calibration.read(tmp_path / "new.json").hood == Hood(0.12, 0.002, 0.95, (0.054, 0.0, 0.88), 40)
    d = json.loads((tmp_path / "new.json").read_text())
    d["hood"]["share"] = 1.5
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"bad\.json: hood"):
        Calibration.read(tmp_path / "bad.json")


def test_the_model_frame_does_not_see_the_hood():
    model, mounting = model_camera((128, 256))
    blocked = np.zeros((256, 512), bool)
    blocked[224:] = True                                    # the bottom eighth of a frame twice the size
    mf = ModelFrame.resize_only(model, mounting, 512, 256)
    cut = ModelFrame(model.scaled(512, 256), (), mounting, model, mounting, blocked)
    assert mf.seen.all()
    assert not cut.seen[112:].any() and cut.seen[:112].all()
    with pytest.raises(ValueError, match="blocked"):
        ModelFrame(model.scaled(512, 256), (), mounting, model, mounting, blocked[:100])


def test_bsn_run_without_a_camera_file_finds_the_hood_and_masks_it(clips):
    card = card_for((128, 256))
    truth = Rig.draw(HOODS[1]).hood
    camera = CameraState(card, background=False, hood=HoodConfig(frames=FRAMES))
    camera.use_frame_rate(CameraState.CALIBRATE_HZ)      # every frame fed
    frames = frames_of(clips[HOODS[1]])
    for f in frames[:10]:
        camera.observe(f)
    assert camera.hood is None and camera.summary()["hood"] is None
    assert camera.hood_progress().startswith(f"still looked for: 10 of the {FRAMES} frames")
    for f in frames[10:]:
        camera.observe(f)
    assert camera.hood_progress() == ""
    assert camera.hood is not None and abs(camera.hood.share - truth) < 0.015
    assert camera.summary()["hood"]["share"] == round(camera.hood.share, 4)
    seen = camera.frame_for(frames[-1]).seen
    painted = camera.camera_file(256, 128).model_frame(256, 128, card.camera, card.mounting,
                                                       mounting=camera.mounting or card.mounting)
    # what the model frame does not see is the painted hood warped into it (and the picture's edge)
    want = painted.labels_to_model(hood_mask(256, 128, truth).astype(np.uint8)) > 0
    hidden = ~seen & painted.labels_to_model(np.ones((128, 256), np.uint8)).astype(bool)
    assert (hidden == want).mean() > 0.98 and want.sum() > 500
    assert cv2.countNonZero(hidden.astype(np.uint8)) > 0


def _corner_hood(width: int, height: int) -> np.ndarray:
    """A hood seen in the right-hand corner only, as a camera mounted to the left of the car's axis
    sees it: its outline (a quadratic, with x from -1 to 1) leaves the bottom edge at 60 % of the
    width (x = 0.2) and rises to 9 % of the rows at the right edge."""
    t = ((np.arange(width) + 0.5 - width / 2.0) / (width / 2.0) - 0.2) / 0.8
    top = height * (1.0 - 0.09 * (0.6 * t + 0.4 * t ** 2))
    return np.arange(height)[:, None] + 0.5 >= top[None, :]


def test_a_hood_in_one_corner_is_found_and_only_it_is_masked(clips):
    frames = frames_of(clips[BARE[0]])
    hood = _corner_hood(256, 128)
    painted = []
    for i, f in enumerate(frames):
        g = f.copy()
        # a glossy hood: bright paint with a faint mirror of the scene that changes with it
        g[hood] = np.clip(200 + 0.05 * f[hood].astype(np.float32) + (i % 3), 0, 255).astype(np.uint8)
        painted.append(g)
    found = find_hood(painted)
    assert found.found and abs(found.share - 0.09) < 0.015 + 3 * found.spread, found
    mask = found.mask(256, 128)
    assert (mask & hood).sum() / (mask | hood).sum() > 0.8
    assert not mask[:, :128].any()                           # the left half shows no hood


def test_a_real_hood_in_one_corner_is_found():
    """mountain_highway.mp4: a glossy white hood in the bottom-right corner, which mirrors the sky.
    Read by eye: its outline leaves the bottom edge near 60 % of the width and rises to about 7 %
    of the rows at the right edge; none at the left."""
    clip = REAL / "mountain_highway.mp4"
    if not clip.is_file():
        pytest.skip(f"real data absent: {clip}")
    frames = read_video(clip, max_frames=100)[::2]          # about online calibration's rate (12.5 Hz)
    hood = find_hood(frames)
    assert hood.found and 0.04 < hood.share < 0.09, hood
    mask = hood.mask(640, 360)
    assert mask[350:, 600:].mean() > 0.9 and not mask[:, :320].any()


def test_a_camera_files_hood_is_judged_by_the_mask_its_arch_draws():
    """Worked by hand on the 90x160 grid: an arch at 0.9 of the height masks rows 81-89, 10 % of the
    picture; an arch at the top row masks all of it, whatever its ``share`` says (0.1), and is refused;
    an arch that is not three finite numbers is refused."""
    from bsn_edge.calibration.hood import MAX_MASKED, Hood

    base = {"share": 0.1, "spread": 0.0, "columns": 1.0, "frames": 5}
    assert Hood.from_dict({**base, "arch": [0.0, 0.0, 0.9]}).mask(160, 90).mean() == pytest.approx(0.1)
    with pytest.raises(ValueError, match=r"masks 100 % of the picture \(at most 35 %\)"):
        Hood.from_dict({**base, "arch": [0, 0, 0]})
    with pytest.raises(ValueError, match="at most 35 %"):
        Hood.from_dict({**base, "arch": [0.0, 0.0, 1 - MAX_MASKED - 0.02]})
    Hood.from_dict({**base, "arch": [0.0, 0.0, 1 - MAX_MASKED + 0.02]})
    for arch in ([float("nan"), 0, 0], [True, 0, 0], [0, 0, float("inf")]):
        with pytest.raises(ValueError, match="three finite numbers"):
            Hood.from_dict({**base, "arch": arch})
