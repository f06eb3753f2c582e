"""On-disk formats shared by every stage."""

import json
import signal
import subprocess
import sys

import numpy as np
import pytest

from bsn_edge.camera import Intrinsics, look_pose
from bsn_edge.sequence import (
    SequenceMeta,
    atomic_write_bytes,
    read_depth,
    read_kitti_poses,
    read_mask,
    read_poses,
    read_tum_poses,
    torn_writes,
    write_depth,
    write_kitti_poses,
    write_mask,
)


def test_depth_png_roundtrip(tmp_path):
    d = np.array([[0.0, 1.0, 12.345], [80.0, 255.99, np.nan]], np.float32)
    write_depth(tmp_path / "d.png", d)
    back = read_depth(tmp_path / "d.png")
    assert back[1, 2] == 0 and back[0, 0] == 0
    assert np.abs(back[:, :2] - d[:, :2]).max() <= 0.5 / 256
    assert back[0, 2] == pytest.approx(12.345, abs=0.5 / 256)


def test_depth_reader_rejects_8bit(tmp_path):
    write_mask(tmp_path / "m.png", np.ones((4, 4), bool))
    with pytest.raises(ValueError, match="16-bit"):
        read_depth(tmp_path / "m.png")


def test_mask_roundtrip(tmp_path):
    m = np.random.default_rng(0).random((10, 12)) > 0.5
    write_mask(tmp_path / "m.png", m)
    assert np.array_equal(read_mask(tmp_path / "m.png"), m)


def test_missing_image_names_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.png"):
        read_mask(tmp_path / "nope.png")


def test_kitti_poses_roundtrip(tmp_path):
    poses = np.stack([look_pose(np.array([i, 2.0 * i, 1.5]), 0.1 * i, 0.02) for i in range(5)])
    write_kitti_poses(tmp_path / "p.txt", poses)
    np.testing.assert_allclose(read_kitti_poses(tmp_path / "p.txt"), poses, atol=1e-8)
    np.testing.assert_allclose(read_poses(tmp_path / "p.txt"), poses, atol=1e-8)


def test_kitti_poses_read_a_literal_line_row_major(tmp_path):
    """KITTI: 12 numbers, the 3x4 [R | t] row by row. A rotation that is not symmetric (90 degrees
    about z) catches a transposed reader or writer, which a round trip would not."""
    (tmp_path / "p.txt").write_text("0 -1 0 1.5 1 0 0 2.5 0 0 1 3.5\n")
    pose = read_kitti_poses(tmp_path / "p.txt")[0]
    np.testing.assert_array_equal(pose[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_array_equal(pose[:3, 3], [1.5, 2.5, 3.5])
    write_kitti_poses(tmp_path / "q.txt", pose[None])
    assert [float(x) for x in (tmp_path / "q.txt").read_text().split()] == [0, -1, 0, 1.5, 1, 0, 0, 2.5, 0, 0, 1, 3.5]


def test_kitti_bad_line_says_where(tmp_path):
    (tmp_path / "p.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0\n")
    with pytest.raises(ValueError, match=r"p.txt:2: .*12 numbers"):
        read_kitti_poses(tmp_path / "p.txt")


def test_tum_poses(tmp_path):
    # 90 degrees about z: q = (0, 0, sin 45, cos 45)
    s = np.sqrt(0.5)
    (tmp_path / "t.txt").write_text(f"# tum\n0.0 1 2 3 0 0 {s} {s}\n0.1 4 5 6 0 0 0 1\n")
    stamps, poses = read_tum_poses(tmp_path / "t.txt")
    np.testing.assert_allclose(stamps, [0.0, 0.1])
    np.testing.assert_allclose(poses[0, :3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(poses[1, :3, 3], [4, 5, 6])
    np.testing.assert_allclose(read_poses(tmp_path / "t.txt"), poses)


def test_meta_roundtrip_and_errors(tmp_path):
    m = SequenceMeta(fps=10, intrinsics=Intrinsics(300, 300, 256, 128, 512, 256), source="synth",
                     frames=5, seed=1, extra={"style": "town"})
    m.write(tmp_path)
    written = json.loads((tmp_path / "meta.json").read_text())
    assert written == {"fps": 10, "width": 512, "height": 256, "fx": 300, "fy": 300, "cx": 256, "cy": 128,
                       "source": "synth", "frames": 5, "seed": 1, "style": "town"}
    back = SequenceMeta.read(tmp_path)
    assert back == m and back.intrinsics.K[0, 0] == 300 and (back.width, back.height) == (512, 256)
    (tmp_path / "meta.json").write_text('{"fps": 10}')
    with pytest.raises(ValueError, match="missing keys"):
        SequenceMeta.read(tmp_path)
    with pytest.raises(FileNotFoundError, match="not a sequence folder"):
        SequenceMeta.read(tmp_path / "nowhere")
    (tmp_path / "meta.json").write_text(json.dumps({**written, "fx": -1}))
    with pytest.raises(ValueError, match="focal"):
        SequenceMeta.read(tmp_path)
    (tmp_path / "meta.json").write_text(json.dumps({**written, "cy": "middle"}))
    with pytest.raises(ValueError, match=r"meta\.json.*cy|cy.*meta\.json"):
        SequenceMeta.read(tmp_path)


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    atomic_write_bytes(tmp_path / "ok.bin", b"abc")
    assert (tmp_path / "ok.bin").read_bytes() == b"abc"
    with pytest.raises(TypeError):
        atomic_write_bytes(tmp_path / "bad.bin", "not bytes")  # type: ignore[arg-type]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.bin"]


def test_a_write_killed_part_way_leaves_a_temporary_file_that_torn_writes_finds(tmp_path):
    """A child process SIGKILLed between writing and renaming: the target is untouched, and only
    the file it left is found (not a neighbour's, not a user's look-alike)."""
    child = (
        "import os, signal, sys\n"
        "from bsn_edge.sequence import atomic_write_bytes\n"
        "os.replace = lambda a, b: os.kill(os.getpid(), signal.SIGKILL)\n"
        "atomic_write_bytes(sys.argv[1], b'new')\n"
    )
    target = tmp_path / "state.pt"
    target.write_bytes(b"old")
    keep = [tmp_path / n for n in ("state.pt.tmp", ".state.pt.tmp", ".other.pt.x.tmp", ".state.pt.x.bak")]
    for p in keep:
        p.write_bytes(b"x")
    done = subprocess.run([sys.executable, "-c", child, str(target)], check=False)
    assert done.returncode == -signal.SIGKILL
    left = set(tmp_path.iterdir()) - set(keep) - {target}
    assert len(left) == 1 and next(iter(left)).read_bytes() == b"new" and target.read_bytes() == b"old"
    assert torn_writes(target) == sorted(left)
    assert torn_writes(tmp_path / "absent" / "state.pt") == []


def test_intrinsics_scaling_is_one_place():
    k = Intrinsics.from_fov(1024, 512, 80.0)
    s = k.scaled(512, 256)
    assert s.fx == pytest.approx(k.fx / 2) and (s.width, s.height) == (512, 256)
    # a point of the image keeps its ray: full-size pixel u is (u + 0.5) / 2 - 0.5 at half size
    u = 201.0
    assert (u - k.cx) / k.fx == pytest.approx(((u + 0.5) / 2 - 0.5 - s.cx) / s.fx)
    with pytest.raises(ValueError):
        Intrinsics(0, 1, 0, 0, 10, 10)


def test_tum_write_read_roundtrip(tmp_path):
    from bsn_edge.sequence import write_tum_poses
    rng = np.random.default_rng(1)
    poses = np.stack([look_pose(rng.normal(size=3), *rng.uniform(-3, 3, 2)) for _ in range(20)])
    write_tum_poses(tmp_path / "t.txt", np.arange(20) * 0.1, poses)
    np.testing.assert_allclose(read_tum_poses(tmp_path / "t.txt")[1], poses, atol=1e-8)


def test_a_users_meta_without_frames_counts_the_folder(tmp_path):
    """A clip written to the documented format by hand: frames derived from rgb/."""
    import json

    import numpy as np

    from bsn_edge.sequence import SequenceMeta, write_image
    from bsn_edge.sequence.folder import SequenceFolder

    seq = SequenceFolder(tmp_path / "mine")
    (seq.path / "rgb").mkdir(parents=True)
    for i in range(7):
        write_image(seq.rgb(i), np.zeros((32, 64, 3), np.uint8))
    seq.meta_path.write_text(json.dumps({"fps": 10, "width": 64, "height": 32, "fx": 40, "fy": 40, "cx": 32,
                                         "cy": 16}))
    meta = SequenceMeta.read(seq.path)
    assert meta.frames == 7 and meta.source == "user"
    assert seq.rgb(3).name == "000003.png" and seq.labels("T5s").blindspot(3).parts[-3:] == (
        "T5s", "blindspot", "000003.png")
