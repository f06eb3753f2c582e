"""What a new user trips over first: files with missing fields, hints that name the way out, sizes
and ranges checked before any work, messages without Python in them."""

import json
import re
from pathlib import Path

import pytest

from bsn_edge.calibration import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.cli import run as run_cli
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.mounting import Mounting

ROOT = Path(__file__).resolve().parents[2]
MODEL = DEFAULT_MODEL


def camera_file(tmp_path: Path, **changes) -> Path:
    cal = Calibration.of(Intrinsics.from_fov(1280, 720, 90.0), (), Mounting(1.3, 2.0, 0.5, 0.2))
    d = cal.to_dict()
    for dotted, value in changes.items():
        *parents, key = dotted.split("__")
        node = d
        for part in parents:
            node = node[part]
        if value is None:
            del node[key]
        else:
            node[key] = value
    p = tmp_path / "cam.json"
    p.write_text(json.dumps(d))
    return p


@pytest.mark.parametrize("field", ["pitch_deg", "yaw_deg", "roll_deg", "height_m"])
def test_a_camera_file_without_a_mounting_angle_is_refused_by_name(tmp_path, field):
    p = camera_file(tmp_path, **{f"mounting__{field}": None})
    with pytest.raises(ValueError, match=rf"cam\.json: mounting: field '{field}' is missing"):
        Calibration.read(p)


@pytest.mark.parametrize(("field", "value"), [("fx", None), ("width", "1280"), ("cy", True), ("height", 720.5)])
def test_a_camera_file_with_a_missing_or_non_numeric_intrinsic_is_refused_by_name(tmp_path, field, value):
    p = camera_file(tmp_path, **{field: value})
    with pytest.raises(ValueError, match=rf"cam\.json: field '{field}'") as e:
        Calibration.read(p)
    assert "__init__" not in str(e.value) and "positional" not in str(e.value)


def test_bsn_run_refuses_a_camera_file_without_pitch_before_any_frame(tmp_path, capsys):
    p = camera_file(tmp_path, mounting__pitch_deg=None)
    log = tmp_path / "alerts.jsonl"
    code = run_cli.main(["--model", str(MODEL), "--source", str(tmp_path / "none.mp4"), "--calib", str(p),
                         "--log", str(log)])
    err = capsys.readouterr().err
    assert code != 0
    assert "pitch_deg" in err and "cam.json" in err and "Traceback" not in err
    assert not log.exists() or log.read_text() == ""


def test_sizes_are_printed_as_typed_and_bad_ones_say_what_is_wrong(tmp_path, capsys):
    from bsn_edge.cli import synth as synth_cli
    assert synth_cli.main([str(tmp_path / "c"), "--frames", "2", "--size", "64x128", "--no-video"]) == 0
    assert "at 64x128" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        synth_cli.main([str(tmp_path / "d"), "--size", "-5x10"])
    err = capsys.readouterr().err
    assert "positive whole numbers" in err and "expected one argument" not in err


def test_bsn_synth_refuses_a_full_folder_in_one_line_and_no_progress_before_it(tmp_path, capsys):
    from bsn_edge.cli import synth as synth_cli
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "mine.txt").write_text("keep")
    assert synth_cli.main([str(tmp_path / "c"), "--frames", "2", "--size", "64x128", "--no-video"]) == 2
    printed = capsys.readouterr()
    lines = [ln for ln in (printed.out + printed.err).replace("\r", "\n").splitlines() if ln.strip()]
    assert lines == [f"bsn-synth: error: {tmp_path / 'c'} already exists and is not empty; pass --force to "
                     "overwrite it"]
    assert [p.name for p in (tmp_path / "c").iterdir()] == ["mine.txt"]


@pytest.mark.parametrize(("flag", "value", "words"), [("--height", "7", "[0.2, 5]"), ("--lane-width", "12", "[2, 6]")])
def test_calibrate_checks_its_ranges_before_reading_the_video(tmp_path, capsys, flag, value, words):
    from bsn_edge.cli import calibrate as calib_cli
    cam = camera_file(tmp_path)
    missing = tmp_path / "never_read.mp4"       # not there: a range error must come first
    out = tmp_path / "o.json"
    code = calib_cli.main([str(missing), "--mount", "--calib", str(cam), flag, value, "--out", str(out)])
    err = capsys.readouterr().err
    assert code != 0 and words in err and "not found" not in err


def test_the_runtime_and_the_mounting_step_share_one_height_range(tmp_path, capsys):
    cam = camera_file(tmp_path)
    code = run_cli.main(["--model", str(MODEL), "--source", str(tmp_path / "x.mp4"), "--calib", str(cam),
                         "--height", "7"])
    assert code != 0 and "[0.2, 5]" in capsys.readouterr().err


def test_calibrate_on_an_empty_folder_says_no_images(tmp_path, capsys):
    from bsn_edge.cli import calibrate as calib_cli
    (tmp_path / "photos").mkdir()
    code = calib_cli.main([str(tmp_path / "photos"), "--out", str(tmp_path / "cam.json")])
    err = capsys.readouterr().err
    assert code != 0 and "no images found" in err and "0 views" not in err


def test_demo_refuses_a_bad_model_before_rendering(tmp_path, capsys):
    from bsn_edge.cli import demo
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model at all")
    code = demo.main(["--model", str(bad), "--out", str(tmp_path / "demo")])
    assert code != 0
    assert "bad.onnx" in capsys.readouterr().err
    assert not (tmp_path / "demo").exists() or not any((tmp_path / "demo").rglob("*.png")), "nothing rendered"


def test_messages_name_the_file_and_the_way_out_without_python(tmp_path, capsys):
    from bsn_edge.cli import label as label_cli
    from bsn_edge.cli import listen as listen_cli
    video = tmp_path / "clip.mp4"
    video.write_bytes(b"")
    assert listen_cli.main(["--can-log", str(video)]) != 0
    err = capsys.readouterr().err
    assert "clip.mp4" in err and ".log" in err and "ValueError" not in err
    label_cli.main([str(tmp_path / "nothing_here")])
    out = capsys.readouterr()
    text = out.out + out.err
    assert "not a sequence folder" in text and "bsn-synth" in text and "FileNotFoundError" not in text


def test_a_broken_video_gets_one_clean_line(tmp_path):
    import subprocess
    import sys
    video = tmp_path / "broken.mp4"
    video.write_bytes(b"\0" * 64)
    r = subprocess.run([sys.executable, "-m", "bsn_edge.cli.run", "--model", str(MODEL), "--source", str(video)],
                       capture_output=True, text=True, timeout=120)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode != 0
    assert lines == [f"bsn-run: error: {video}: OpenCV cannot open this video"] or \
        (len(lines) == 1 and "broken.mp4" in lines[0]), r.stderr


def test_bsn_run_ends_with_a_short_summary_and_keeps_the_json_for_summary(tmp_path, capsys):
    from bsn_edge.cli import synth as synth_cli
    clip = tmp_path / "clip"
    assert synth_cli.main([str(clip), "--frames", "6", "--size", "96x192", "--seed", "3"]) == 0
    capsys.readouterr()
    summ, log = tmp_path / "s.json", tmp_path / "a.jsonl"
    assert run_cli.main(["--model", str(MODEL), "--source", str(clip / "video.mp4"), "--calib",
                         str(clip / "calibration.json"), "--summary", str(summ), "--log", str(log)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    record = json.loads(summ.read_text())
    assert len(out) <= 6, out
    assert out[0].startswith(f"bsn-run: {record['frames']} frames") and "frames/s" in out[0] and "p99" in out[0]
    assert any(line.strip().startswith("faults: none; on the bus: ") for line in out), out
    assert any(str(log) in line and str(summ) in line for line in out)
    assert not any(line.lstrip().startswith(("{", "\"")) for line in out), "no JSON on the terminal"


def test_eval_with_nothing_held_out_says_the_way_out(tmp_path, capsys):
    from bsn_edge.cli import eval as eval_cli
    from bsn_edge.cli import label as label_cli
    from bsn_edge.cli import synth as synth_cli
    from bsn_edge.cli import train as train_cli
    data = tmp_path / "data"
    assert synth_cli.main([str(data / "town_0"), "--frames", "30", "--size", "64x128", "--no-video"]) == 0
    assert label_cli.main([str(data / "town_0"), "--T", "2", "--jobs", "1"]) == 0
    smoke = str(ROOT / "configs" / "smoke.toml")
    assert train_cli.main(["--config", smoke, "--data", str(data), "--out", str(tmp_path / "run"), "--quiet",
                           "--set", "data.label=\"T2s\"", "--set", "train.steps=1", "--set", "teacher.steps=1"]) == 0
    capsys.readouterr()
    assert eval_cli.main(["--run", str(tmp_path / "run"), "--data", str(data), "--out", str(tmp_path / "e.json")]) == 2
    err = capsys.readouterr().err
    assert "--clips all" in err and "held-out" in err


def test_training_on_labels_of_another_horizon_names_the_one_there(tmp_path):
    from bsn_edge.cli import label as label_cli
    from bsn_edge.cli import synth as synth_cli
    from bsn_edge.data import find_clips
    assert synth_cli.main([str(tmp_path / "town_0"), "--frames", "30", "--size", "64x128", "--no-video"]) == 0
    assert label_cli.main([str(tmp_path / "town_0"), "--T", "2", "--jobs", "1"]) == 0
    with pytest.raises(ValueError, match=re.escape('data.label="T2s"')):
        find_clips(tmp_path, "T5s")


def test_online_calibration_says_how_far_it_got():
    import numpy as np

    from bsn_edge.card import ModelCard
    from bsn_edge.runtime.camera_state import CameraState
    from tests.cards import card_for
    card: ModelCard = card_for((128, 256))
    state = CameraState(card, None)
    assert state.calibrating
    rng = np.random.default_rng(0)
    for _ in range(3):
        state.observe(rng.integers(0, 255, (96, 192, 3), np.uint8))
    text = state.progress()
    assert text.startswith("calibrating:") and "forward driving" in text


def test_the_readme_installs_torch_from_its_cpu_index_before_the_extras():
    readme = (ROOT / "README.md").read_text()
    blocks = readme.split("```bash\n")
    second = next(b.split("```")[0] for b in blocks[1:] if "pytest" in b.split("```")[0])
    cpu = second.find("--index-url https://download.pytorch.org/whl/cpu")
    extras = second.find('-e ".[full,dev,ray]"')
    assert 0 <= cpu < extras, "the CPU build must be installed before [full] pulls torch from the plain index"


def test_the_readme_lists_every_config_and_its_durations_match_the_files():
    readme = (ROOT / "README.md").read_text()
    for cfg in sorted((ROOT / "configs").glob("*.toml")):
        assert f"configs/{cfg.name}" in readme, f"{cfg.name} is not in the README"
    quick = (ROOT / "configs" / "quick.toml").read_text().splitlines()[0]
    assert "20 minutes" in quick and "quick.toml` (about 20 minutes" in readme


def test_a_config_value_of_the_wrong_kind_names_the_key_and_where_it_came_from(tmp_path):
    from bsn_edge.train import load_config
    bad = tmp_path / "bad.toml"
    bad.write_text('[train]\nlr = "fast"\n')
    with pytest.raises(ValueError, match=r"train\.lr = 'fast' \(.*bad\.toml\) must be a finite number"):
        load_config(bad)
    with pytest.raises(ValueError, match=r"train\.steps = 'abc' \(--set\) must be a whole number"):
        load_config(ROOT / "configs" / "smoke.toml", ["train.steps=abc"])


def test_bsn_listen_fails_on_a_log_that_holds_no_frame(tmp_path, capsys):
    from bsn_edge.cli import listen as listen_cli
    empty = tmp_path / "empty.log"
    empty.write_text("")
    assert listen_cli.main(["--can-log", str(empty)]) == 1
    assert f"{empty}: holds no frame" in capsys.readouterr().err
