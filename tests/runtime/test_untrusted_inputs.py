"""Inputs that are not what their names say: a FIFO named like a picture, a key or a settings file, a picture
that is a link to /dev/zero, a model the size of a disk. Nothing is opened in a way that blocks or read past
its budget: each is refused by name (before the first frame, exit 2) or counted as a damaged frame, and the
run ends with its summary. Every run here is a real process with a generous deadline that only catches a
hang (``BUSY_S``)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

from bsn_edge.cli.common import CHECKOUT
from tests.fakes import BUSY_S


def bsn_run(*argv: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    return subprocess.run([sys.executable, "-m", "bsn_edge.cli.run", *argv], capture_output=True, text=True,
                          env=env, timeout=6 * BUSY_S)


def test_a_fifo_and_a_link_to_dev_zero_among_the_pictures_are_damaged_frames_not_a_hang(setup, tmp_path):
    model, clip = setup
    frames = tmp_path / "frames"
    shutil.copytree(clip / "rgb", frames)
    os.mkfifo(frames / "000000_fifo.png")            # sorts first: the folder's size is sniffed from it
    os.symlink("/dev/zero", frames / "000007_zero.png")
    summary = tmp_path / "s.json"
    r = bsn_run("--model", str(model), "--source", str(frames), "--summary", str(summary), "--allow-unsigned")
    s = json.loads(summary.read_text())
    assert s["frames"] == 17 and s["valid_frames"] == 15, (r.returncode, r.stderr[-500:])
    assert s["faults"]["decode_errors"] == 2, s["faults"]


def test_a_fifo_or_a_device_as_a_key_a_model_or_the_settings_is_refused_by_name(setup, tmp_path):
    model, clip = setup
    fifo = tmp_path / "key.pub"
    os.mkfifo(fifo)
    zero = tmp_path / "model.onnx"
    os.symlink("/dev/zero", zero)
    settings = tmp_path / "v.toml"
    os.mkfifo(settings)
    for argv, says in ((["--model", str(model), "--trust", str(fifo)], "is a FIFO, not a file"),
                       (["--model", str(zero)], "is a character device, not a file"),
                       (["--model", str(model), "--config", str(settings)], "is a FIFO, not a file")):
        r = bsn_run(*argv, "--source", str(clip / "video.mp4"), "--max-frames", "2")
        assert r.returncode == 2 and says in r.stderr, (argv, r.returncode, r.stderr[-400:])


def test_a_model_over_its_budget_is_refused_from_its_size_unread(setup, tmp_path):
    _, clip = setup
    huge = tmp_path / "huge.onnx"
    with open(huge, "wb") as f:                      # sparse: 2 GB on paper, nothing on the disk
        f.truncate(2 << 30)
    r = bsn_run("--model", str(huge), "--source", str(clip / "video.mp4"), "--max-frames", "2")
    assert r.returncode == 2 and "over the 512.0 MB a model may be" in r.stderr, r.stderr[-400:]


def test_a_video_too_small_or_too_wide_is_refused_before_its_first_frame(setup, tmp_path):
    """No camera file given, yet once refused mid-run naming one; now before the first frame, rc 2."""
    import cv2
    import numpy as np

    model, _ = setup
    for w, h in ((12, 10), (9000, 20)):
        video = tmp_path / f"v{w}.avi"
        out = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (w, h))
        for _ in range(3):
            out.write(np.random.default_rng(0).integers(0, 255, (h, w, 3), dtype=np.uint8))
        out.release()
        summary = tmp_path / f"s{w}.json"
        r = bsn_run("--model", str(model), "--source", str(video), "--summary", str(summary))
        assert r.returncode == 2 and f"frames of {w}x{h}" in r.stderr, (r.returncode, r.stderr[-300:])
        assert json.loads(summary.read_text())["frames"] == 0


def test_a_full_stdout_or_stderr_loses_only_what_was_printed(setup, tmp_path):
    """Standard error on a full disk once lost the summary (rc 1, silent), standard output ended in a
    traceback (rc 1): with both on a full disk the drive, the bus and the summary go on (rc 0), and what
    could not be printed while it ran is named in the summary (the end lines come after it is written)."""
    model, clip = setup
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    summary, log = tmp_path / "s.json", tmp_path / "c.log"
    with open("/dev/full", "w") as full:
        r = subprocess.run([sys.executable, "-m", "bsn_edge.cli.run", "--model", str(model), "--source",
                            str(clip / "video.mp4"), "--summary", str(summary), "--can-log", str(log),
                            "--allow-unsigned"], env=env, timeout=6 * BUSY_S, stdout=full, stderr=full)
    s = json.loads(summary.read_text())
    assert r.returncode == 0 and s["frames"] == 15, r.returncode
    assert s["console"]["stderr"]["error"] == "No space left on device", s["console"]
