"""``label_sequence`` and ``bsn-label`` over sequence folders."""

import dataclasses
import json
import shutil

import cv2
import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.calibration import Calibration
from bsn_edge.cli import label as label_cli
from bsn_edge.labels import LabelConfig, Sources, label_sequence, labels_dir, resample
from bsn_edge.labels.generator import StaleLabelsError
from bsn_edge.semantics import CAR, VEHICLES
from bsn_edge.sequence import read_depth, read_kitti_poses, read_mask, write_depth, write_kitti_poses, write_tum_poses
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.images import MAX_DEPTH_M
from bsn_edge.synth import SynthConfig, write_clip
from bsn_edge.synth.rig import Rig

CFG = LabelConfig(rate=5.0, horizon_s=1.0)  # T = 5 label frames


@pytest.fixture(scope="module")
def clip_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("clips") / "town"
    write_clip(SynthConfig(frames=30, height=64, width=128, fps=10.0, seed=2), out, video=False)
    return out


@pytest.fixture
def seq(clip_dir, tmp_path):
    dst = tmp_path / "seq"
    shutil.copytree(clip_dir, dst)
    return dst


def test_resample_picks_nearest_frames():
    assert resample(30, 10.0, 5.0).tolist() == list(range(0, 30, 2))
    assert resample(10, 5.0, 5.0).tolist() == list(range(10))
    assert resample(7, 15.0, 5.0).tolist() == [0, 3, 6]
    with pytest.raises(ValueError, match="above the clip"):
        resample(10, 5.0, 10.0)


def test_labels_report_and_tail(seq):
    rep = label_sequence(seq, CFG)
    out = labels_dir(seq, CFG)
    assert out.name == "T1s"
    # 15 frames at 5 fps, T = 5: the last 5 have no complete window and get no label
    assert rep["label_frames"] == 10 and rep["unlabelled_tail_frames"] == 5
    names = sorted(p.name for p in (out / "blindspot").iterdir())
    assert names == [f"{i:06d}.png" for i in range(0, 20, 2)], "labels carry the source frame's name"
    assert sorted(p.name for p in (out / "visibility").iterdir()) == names
    saved = json.loads((out / "report.json").read_text())
    assert saved["config"]["depth_tol"] == 1.0 and saved["config"]["horizon_frames"] == 5
    assert saved["sources"] == {"depth": "files", "seg": "files", "poses": "files", "calib": ""}
    assert len(saved["per_frame"]) == 10 and saved["status"] == "ok"
    assert read_mask(out / "visibility" / "000000.png").any()
    assert not list(seq.rglob("*.tmp"))


def test_rerun_resumes_and_keeps_finished_frames(seq):
    label_sequence(seq, CFG)
    out = labels_dir(seq, CFG)
    first = (out / "blindspot" / "000004.png").read_bytes()
    (out / "blindspot" / "000006.png").unlink()   # as if interrupted there
    rep = label_sequence(seq, CFG)
    assert rep["resumed_frames"] == 9 and rep["label_frames"] == 10
    assert (out / "blindspot" / "000004.png").read_bytes() == first
    assert (out / "blindspot" / "000006.png").exists()


def test_pose_count_mismatch_is_explained(seq):
    poses = read_kitti_poses(seq / "poses.txt")
    write_kitti_poses(seq / "poses.txt", poses[:-3])
    with pytest.raises(ValueError, match="27 poses for 30 frames"):
        label_sequence(seq, CFG)


def test_missing_depth_files_are_named(seq):
    (seq / "depth" / "000011.png").unlink()
    with pytest.raises(FileNotFoundError, match=r"1 of 30 frames missing \(000011\.png"):
        label_sequence(seq, CFG)


def test_tum_trajectory_file_gives_the_same_labels(seq, tmp_path):
    poses = read_kitti_poses(seq / "poses.txt")
    stamps = 1700000000.0 + np.arange(len(poses)) / 10.0 + 0.004  # a SLAM's clock, slightly off
    write_tum_poses(tmp_path / "traj.txt", stamps, poses)
    ref = label_sequence(seq, CFG)
    shutil.rmtree(labels_dir(seq, CFG))
    rep = label_sequence(seq, CFG, Sources(poses=str(tmp_path / "traj.txt")))
    assert rep["sources_detail"]["poses"]["kind"] == "trajectory"
    a = [f["blindspot_px"] for f in ref["per_frame"]]
    b = [f["blindspot_px"] for f in rep["per_frame"]]
    assert np.abs(np.subtract(a, b)).max() <= 2


def test_tum_with_a_gap_is_explained(seq, tmp_path):
    poses = read_kitti_poses(seq / "poses.txt")
    stamps = np.arange(len(poses)) / 10.0
    stamps[12:] += 1.0
    write_tum_poses(tmp_path / "traj.txt", stamps, poses)
    with pytest.raises(ValueError, match="no pose within half a frame of frame 12"):
        label_sequence(seq, CFG, Sources(poses=str(tmp_path / "traj.txt")))


def test_cli_labels_good_clips_and_reports_bad_ones(seq, tmp_path, capsys):
    bad = tmp_path / "bad"
    shutil.copytree(seq, bad)
    meta = json.loads((bad / "meta.json").read_text())
    meta["fx"] = 0.0
    (bad / "meta.json").write_text(json.dumps(meta))
    rc = label_cli.main([str(seq), str(bad), str(tmp_path / "nowhere"), "--T", "1", "--jobs", "2"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "focal lengths must be positive" in out and "not a sequence folder" in out
    assert len(list((labels_dir(seq, CFG) / "blindspot").iterdir())) == 10, "the good clip is labelled"
    assert label_cli.main([str(seq), "--T", "1"]) == 0
    assert "10 frames (10 already done)" in capsys.readouterr().out


def test_cli_rejects_bad_parameters(seq, capsys):
    assert label_cli.main([str(seq), "--T", "0"]) == 2
    assert "horizon T must be positive" in capsys.readouterr().err
    assert label_cli.main([str(seq), "--T", "1", "--depth", "lidar"]) == 1
    assert "unknown depth source 'lidar'" in capsys.readouterr().out


def test_labels_are_deterministic(seq, tmp_path):
    other = tmp_path / "again"
    shutil.copytree(seq, other)
    label_sequence(seq, CFG)
    label_sequence(other, CFG)
    for p in sorted((labels_dir(seq, CFG) / "blindspot").iterdir()):
        assert np.array_equal(read_mask(p), read_mask(labels_dir(other, CFG) / "blindspot" / p.name))


def test_calibration_file_replaces_the_intrinsics(seq, tmp_path):
    from bsn_edge.calibration import Calibration
    from bsn_edge.camera import Intrinsics
    from bsn_edge.sequence import SequenceMeta
    m = SequenceMeta.read(seq).intrinsics
    # the same camera described at twice the size: rescaled, it is identical, so are the labels
    Calibration(Intrinsics(m.fx * 2, m.fy * 2, (m.cx + 0.5) * 2 - 0.5, (m.cy + 0.5) * 2 - 0.5, m.width * 2,
                           m.height * 2)).write(tmp_path / "c.json")
    ref = label_sequence(seq, CFG)
    shutil.rmtree(labels_dir(seq, CFG))
    rep = label_sequence(seq, CFG, Sources(calib=str(tmp_path / "c.json")))
    assert [f["blindspot_px"] for f in rep["per_frame"]] == [f["blindspot_px"] for f in ref["per_frame"]]
    same = {p.name: read_mask(p) for p in (labels_dir(seq, CFG) / "blindspot").iterdir()}
    # a camera that differs (a longer lens, a lower centre) is used, not ignored: other masks
    Calibration(Intrinsics(m.fx * 1.4, m.fy * 1.4, m.cx, m.cy + 6, m.width, m.height)).write(tmp_path / "d.json")
    label_sequence(seq, CFG, Sources(calib=str(tmp_path / "d.json")), force=True)
    other = {p.name: read_mask(p) for p in (labels_dir(seq, CFG) / "blindspot").iterdir()}
    assert other.keys() == same.keys()
    changed = sum(int((other[k] != same[k]).sum()) for k in same)
    assert changed > 0.2 * sum(int(v.sum()) for v in same.values())


def test_the_calibrated_camera_is_recorded_where_training_reads_it(seq, tmp_path):
    """bsn-label --calib: the calibration's intrinsics (at the clip's size) go with the labels, and
    training takes the model card's camera from there."""
    from bsn_edge.calibration import Calibration
    from bsn_edge.camera import Intrinsics
    from bsn_edge.labels.generator import label_camera
    from bsn_edge.sequence import SequenceMeta
    from bsn_edge.sequence.folder import SequenceFolder
    m = SequenceMeta.read(seq).intrinsics
    Calibration(Intrinsics(m.fx * 2.2, m.fy * 2.2, m.width, m.height, m.width * 2, m.height * 2)).write(
        tmp_path / "c.json")
    label_sequence(seq, CFG, Sources(calib=str(tmp_path / "c.json")))
    cam = label_camera(SequenceFolder(seq).labels(CFG.name))
    assert (cam.width, cam.height) == (m.width, m.height)
    assert cam.fx == pytest.approx(m.fx * 1.1) and cam.fy == pytest.approx(m.fy * 1.1)


def test_a_rerun_with_other_parameters_refuses_then_relabels_with_force(seq, capsys):
    assert label_cli.main([str(seq), "--T", "1", "--jobs", "1"]) == 0
    out = labels_dir(seq, CFG)
    before = {p.name: p.read_bytes() for p in (out / "blindspot").iterdir()}
    argv = [str(seq), "--T", "1", "--jobs", "1", "--depth-tol", "3", "--vis-range", "5", "--min-area", "5000"]
    capsys.readouterr()
    assert label_cli.main(argv) == 1
    text = capsys.readouterr().out
    assert "stale" in text and "depth_tol 1.0 -> 3.0" in text and "--force" in text
    assert {p.name: p.read_bytes() for p in (out / "blindspot").iterdir()} == before, "nothing was touched"
    assert json.loads((out / "report.json").read_text())["config"]["depth_tol"] == 1.0
    assert label_cli.main([*argv, "--force"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["config"]["depth_tol"] == 3.0 and rep["resumed_frames"] == 0
    assert json.loads((out / "params.json").read_text())["config"]["min_area"] == 5000
    # min-area 5000 px on a 64x128 frame leaves no component
    assert not any(read_mask(p).any() for p in (out / "blindspot").iterdir())
    assert label_cli.main([*argv]) == 0 and "10 frames (10 already done)" in capsys.readouterr().out


def test_labels_recorded_before_a_setting_existed_resume_at_its_default(seq):
    label_sequence(seq, CFG)
    params = labels_dir(seq, CFG) / "params.json"
    rec = json.loads(params.read_text())
    del rec["config"]["look_tol"]                   # a record written before the look check
    params.write_text(json.dumps(rec))
    assert label_sequence(seq, CFG)["resumed_frames"] == 10
    with pytest.raises(StaleLabelsError, match=r"look_tol 0\.0 -> 8\.0"):
        label_sequence(seq, LabelConfig(rate=5.0, horizon_s=1.0, look_tol=8.0))


def _spill_car_outlines(seq, grow_px: int = 2) -> None:
    """Depth and classes as a segmentation model gives them: every vehicle's outline spills
    ``grow_px`` pixels onto what surrounds it, which takes the car's class and its nearest depth."""
    k = np.ones((2 * grow_px + 1,) * 2, np.uint8)
    for p in sorted((seq / "semantic").iterdir()):
        s = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        d = read_depth(seq / "depth" / p.name)
        car = np.isin(s, VEHICLES).astype(np.uint8)
        grown = cv2.dilate(car, k).astype(bool) & ~car.astype(bool)
        nearest = cv2.erode(np.where(car > 0, d, MAX_DEPTH_M).astype(np.float32), k)
        s[grown], d[grown] = CAR, nearest[grown]
        cv2.imwrite(str(p), s)
        write_depth(seq / "depth" / p.name, d)


def _precision(seq, cfg) -> float:
    tp = fp = 0
    for p in sorted((labels_dir(seq, cfg) / "blindspot").iterdir()):
        got, true = read_mask(p), read_mask(seq / "bsgt" / p.name)
        tp, fp = tp + int((got & true).sum()), fp + int((got & ~true).sum())
    return tp / (tp + fp)


def test_the_look_check_removes_car_outlines_and_raises_precision(tmp_path):
    """Car outlines that spill onto the road (as from a segmentation model) make false blind spots
    beside every car; the look check finds the road there and takes them out: precision against
    the clip's true blind spots rises, and the report counts what it removed."""
    seq = tmp_path / "seq"
    write_clip(SynthConfig(frames=30, height=96, width=192, fps=10.0, seed=3), seq, video=False)
    _spill_car_outlines(seq)
    plain, looked = CFG, LabelConfig(rate=5.0, horizon_s=1.0, look_tol=8.0)
    shutil.copytree(seq, tmp_path / "again")
    label_sequence(seq, plain)
    rep = label_sequence(tmp_path / "again", looked)
    assert rep["status"] == "ok" and rep["config"]["look_tol"] == 8.0
    assert sum(f["removed_by_look_px"] for f in rep["per_frame"]) > 100
    assert _precision(tmp_path / "again", looked) > _precision(seq, plain) + 0.03
    with pytest.raises(ValueError, match="look_tol"):
        LabelConfig(look_tol=-1.0)


def test_a_damaged_label_file_is_relabelled_on_resume(seq):
    label_sequence(seq, CFG)
    out = labels_dir(seq, CFG)
    good = (out / "blindspot" / "000008.png").read_bytes()
    (out / "blindspot" / "000008.png").write_bytes(b"")                    # zero length
    (out / "visibility" / "000010.png").write_bytes(b"\x89PNG garbage")    # undecodable
    rep = label_sequence(seq, CFG)
    assert rep["resumed_frames"] == 8
    assert (out / "blindspot" / "000008.png").read_bytes() == good
    assert read_mask(out / "visibility" / "000010.png").shape == (64, 128)


def test_a_clip_too_short_for_T_is_not_labelled_and_says_why(seq, capsys):
    assert label_cli.main([str(seq), "--T", "10", "--jobs", "1"]) == 1
    out = capsys.readouterr().out
    assert "rejected" in out and "too short for T = 10 s" in out and "at least 101 frames" in out


def test_label_workers_end_when_bsn_label_is_killed(tmp_path):
    """SIGKILL the process that started the pool: its workers and the queue's manager go too."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    script = ("import time; from bsn_edge.labels.batch import worker_pool\n"
              "with worker_pool(2) as (pool, q):\n"
              "    fs = [pool.submit(time.sleep, 60) for _ in range(2)]\n"
              "    time.sleep(60)\n")
    parent = subprocess.Popen([sys.executable, "-c", script], cwd=root, env={**os.environ, "PYTHONPATH": str(root)})

    def children() -> list[int]:
        with open(f"/proc/{parent.pid}/task/{parent.pid}/children") as f:
            return [int(x) for x in f.read().split()]

    deadline = time.monotonic() + 60
    kids: list[int] = []
    while time.monotonic() < deadline and len(kids) < 3:   # the manager and two workers
        time.sleep(0.2)
        kids = children()
    assert len(kids) >= 3, kids
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(Path(f"/proc/{k}").exists() and
                                              "Z" not in Path(f"/proc/{k}/stat").read_text().split()[2]
                                              for k in kids):
        time.sleep(0.2)
    alive = [k for k in kids if Path(f"/proc/{k}").exists() and Path(f"/proc/{k}/stat").read_text().split()[2] != "Z"]
    assert not alive, f"still running after their parent was killed: {alive}"


def test_a_distorted_clip_is_labelled_in_its_undistorted_camera(tmp_path):
    """Labels of a clip with barrel distortion land on the true blind spots undistorted by OpenCV
    itself (not by the project's warp), and better than when the lens is ignored."""
    seed = next(s for s in range(300) if Rig.draw(s).k1 < -0.06 and Rig.draw(s).hood == 0)
    out = write_clip(SynthConfig(frames=60, height=192, width=384, seed=seed), tmp_path / "c", video=False)
    cal = Calibration.read(out / "calibration.json")
    m1, m2 = cv2.initUndistortRectifyMap(cal.intrinsics.K, np.array(cal.dist), None, cal.intrinsics.K,
                                         (384, 192), cv2.CV_32FC1)

    def precision() -> tuple[float, int]:
        labels = SequenceFolder(out).labels("T5s")
        tp = fp = 0
        for i in labels.frames():
            bs, vis = read_mask(labels.blindspot(i)), read_mask(labels.visibility(i))
            gt = cv2.remap(read_mask(SequenceFolder(out).bsgt(i)).astype(np.uint8), m1, m2, cv2.INTER_NEAREST) > 0
            tp += int((bs & gt & vis).sum())
            fp += int((bs & ~gt & vis).sum())
        return tp / max(tp + fp, 1), tp

    label_sequence(out, LabelConfig())          # the clip's own calibration.json, with its lens
    with_lens = precision()
    plain = tmp_path / "no_lens.json"
    Calibration.of(cal.intrinsics, (), cal.mounting).write(plain)
    label_sequence(out, LabelConfig(), Sources(calib=str(plain)), force=True)
    without = precision()
    assert with_lens[0] > 0.85 and with_lens[0] > without[0] and with_lens[1] > without[1]
    # the look check compares the undistorted pictures: with exact sources it keeps the labels true
    rep = label_sequence(out, LabelConfig(look_tol=8.0), force=True)
    looked = precision()
    assert looked[0] > 0.85 and looked[1] > 0.7 * with_lens[1]
    assert sum(f["removed_by_look_px"] for f in rep["per_frame"]) > 0


def test_road_users_with_no_road_seen_behind_them_are_left_out_of_v(clip_dir, tmp_path):
    cfg = LabelConfig(rate=5.0, horizon_s=1.0)
    paper, unknown = tmp_path / "paper", tmp_path / "unknown"
    shutil.copytree(clip_dir, paper)
    shutil.copytree(clip_dir, unknown)
    label_sequence(paper, cfg)
    label_sequence(unknown, dataclasses.replace(cfg, users_unknown=True))
    a, b = SequenceFolder(paper).labels(cfg.name), SequenceFolder(unknown).labels(cfg.name)
    left_out = 0
    for i in a.frames():
        sem = cv2.imread(str(SequenceFolder(paper).dir(SequenceFolder.SEMANTIC) / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED)
        users = np.isin(sem, sm.ROAD_USERS)
        omega, v_paper, v_unknown = read_mask(a.blindspot(i)), read_mask(a.visibility(i)), read_mask(b.visibility(i))
        assert np.array_equal(omega, read_mask(b.blindspot(i))), "the blind spots are the paper's"
        assert np.array_equal(v_unknown, v_paper & (omega | ~users))
        left_out += int((v_paper & ~v_unknown).sum())
    assert left_out > 0, "the clip has road users in V without blind spot"
