"""Rendering a whole clip into a sequence folder."""

from __future__ import annotations

import io
import json
import multiprocessing
import shutil
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.camera import Intrinsics, look_pose
from bsn_edge.sequence import SequenceMeta, write_depth, write_image, write_kitti_poses, write_mask
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.images import atomic_write_bytes
from bsn_edge.sequence.meta import RENDERED
from bsn_edge.synth.config import SynthConfig
from bsn_edge.synth.populate import Scenario, build_scenario
from bsn_edge.synth.render import Frame, Renderer
from bsn_edge.synth.rig import Lens, Rig, hood_mask, paint_hood
from bsn_edge.synth.sensor import Sensor, SensorModel

PITCH_DEG = (0.0, 3.0)   # tilt range of "fixed" cameras, degrees down


@dataclass(frozen=True)
class Clip:
    """A scenario with its camera: everything needed to render frame ``i``."""

    config: SynthConfig
    scenario: Scenario
    intrinsics: Intrinsics   # the output frames' (with ``lens``'s distortion)
    poses: np.ndarray        # [N, 4, 4] T_wc
    rig: Rig
    lens: Lens
    sensor: Sensor

    @property
    def pitch(self) -> float:
        return float(np.radians(self.rig.pitch_deg))

    @property
    def times(self) -> np.ndarray:
        return np.arange(self.config.frames) / self.config.fps


def make_clip(cfg: SynthConfig) -> Clip:
    """Build the world, the route and the camera poses of a clip (no rendering yet)."""
    sc = build_scenario(cfg)
    if cfg.camera == "vary":
        rig = Rig.draw(cfg.seed)
    else:
        rng = np.random.default_rng([cfg.seed, 0x706F7365])
        rig = Rig(cfg.hfov_deg, cfg.camera_height, float(rng.uniform(*PITCH_DEG)), roll_deg=cfg.roll_deg)
    times = np.arange(cfg.frames) / cfg.fps
    xy, yaw = sc.route.at(sc.start_s + times * sc.speed)
    # the car's level camera, turned by the mounting: x_cam = R x_level, so R_wc = R_w,level R^T
    turn = np.eye(4)
    turn[:3, :3] = rig.mounting.rotation().T
    poses = np.stack([look_pose(np.array([x, y, rig.height_m]), a, 0.0) @ turn
                      for (x, y), a in zip(xy, yaw, strict=True)])
    intr = rig.intrinsics(cfg.width, cfg.height)
    look = sc.world.look
    sensor = (Sensor.draw(np.random.default_rng([cfg.seed, 0x73656E73]), dark=look.light in ("night", "dusk"))
              if cfg.sensor_effects else Sensor())
    return Clip(cfg, sc, intr, poses, rig, Lens(intr, rig.dist), sensor)


def sensor_model(clip: Clip) -> SensorModel:
    """The clip's sensor on its output frames; motion comes from the car's forward axis."""
    k = clip.intrinsics
    fwd = clip.rig.mounting.rotation() @ np.array([0.0, 0.0, 1.0])
    foe = (k.fx * fwd[0] / fwd[2] + k.cx, k.fy * fwd[1] / fwd[2] + k.cy)
    return SensorModel(clip.sensor, k.width, k.height, foe, k.fx, seed=clip.config.seed)


class _Pipeline:
    """Renders frame ``i`` of a clip: ray casting, lens, sensor, hood."""

    def __init__(self, clip: Clip, renderer: Renderer | None = None) -> None:
        self.clip = clip
        self.r = renderer or Renderer(clip.lens.canvas, far=clip.config.far, bs_range=clip.config.bs_range)
        self.hood = hood_mask(clip.intrinsics.width, clip.intrinsics.height, clip.rig.hood)
        self.develop = sensor_model(clip)

    def frame(self, i: int) -> Frame:
        clip, lens, hood = self.clip, self.clip.lens, self.hood
        fr = self.r.render(clip.scenario.world, clip.poses[i], float(clip.times[i]), frame_index=i, radiance=True)
        rgb = self.develop.develop(lens.apply(fr.rgb), i, clip.scenario.speed)
        if lens.maps is None and not hood.any():
            return Frame(rgb, fr.depth, fr.semantic, fr.bsgt, fr.boxes)
        depth, semantic, bsgt = (lens.apply(fr.depth, nearest=True), lens.apply(fr.semantic, nearest=True),
                                 lens.apply(fr.bsgt, nearest=True))
        if hood.any():
            # the car's own hood: neither road nor a blind spot, no depth the model should learn
            paint_hood(rgb, hood, clip.config.seed)
            depth[hood], semantic[hood], bsgt[hood] = 0.0, sm.IGNORE, False
        return Frame(rgb, depth, semantic, bsgt, fr.boxes)


_WORKER: _Pipeline | None = None
CHUNK = 10   # frames per task when rendering in several processes


def _init_worker(clip: Clip) -> None:
    global _WORKER
    _WORKER = _Pipeline(clip)


def _render_list(indices: list[int]) -> list[Frame]:
    if _WORKER is None:
        raise RuntimeError("a render worker's pipeline is made by its initialiser (_init_worker)")
    return [_WORKER.frame(i) for i in indices]


def render_frames(clip: Clip, renderer: Renderer | None = None, workers: int = 1,
                  indices: Sequence[int] | None = None) -> Iterator[Frame]:
    """Render the clip's frames (all, or ``indices``) in order, in ``workers`` processes (frames are
    independent: a frame is the same bytes whether rendered alone or in the whole clip)."""
    todo = list(range(clip.config.frames)) if indices is None else [int(i) for i in indices]
    if any(not 0 <= i < clip.config.frames for i in todo):
        raise ValueError(f"frame indices must lie in [0, {clip.config.frames}), got {todo}")
    if workers <= 1 or len(todo) < 2 * CHUNK:
        pipe = _Pipeline(clip, renderer)
        for i in todo:
            yield pipe.frame(i)
        return
    chunks = [todo[a:a + CHUNK] for a in range(0, len(todo), CHUNK)]
    # spawned, never forked: a fork copies OpenCV's thread pool mid-lock if this process has used it
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker, initargs=(clip,)) as pool:
        for frames in pool.map(_render_list, chunks):
            yield from frames


def check_output(out: str | Path, force: bool) -> None:
    """``FileExistsError`` when ``out`` cannot take a clip: a file, or a folder with something in it
    (unless ``force``). Touches nothing, so a command can refuse before it starts its work."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder")
    if out.exists() and any(out.iterdir()) and not force:
        raise FileExistsError(f"{out} already exists and is not empty; pass --force to overwrite it")


def prepare_output(out: Path, force: bool) -> None:
    """Create ``out``; refuse a non-empty folder unless ``force``, then clear only what we write."""
    check_output(out, force)
    if out.exists() and any(out.iterdir()):
        for name in (*SequenceFolder.SYNTH_OUTPUTS, SequenceFolder.LABELS):
            p = out / name
            if p.is_dir():
                shutil.rmtree(p)
            elif p.exists():
                p.unlink()
    out.mkdir(parents=True, exist_ok=True)


def write_clip(cfg: SynthConfig, out: str | Path, force: bool = False, video: bool = True,
               progress: Callable[[int], None] | None = None, workers: int = 1) -> Path:
    """Render ``cfg`` into the sequence folder ``out`` and return its path.

    Writes meta.json, poses.txt (KITTI), rgb/, depth/, semantic/, bsgt/, boxes/ (per-frame
    ``[N, 8]`` float32 .npy: trainId, xmin, ymin, zmin, xmax, ymax, zmax, track), video.mp4
    and synth_config.json. ``progress`` is called with 1 after each frame. ``workers`` processes
    render (the bytes do not depend on it).
    """
    out = Path(out)
    prepare_output(out, force)
    seq = SequenceFolder(out)
    clip = make_clip(cfg)
    for sub in SequenceFolder.FRAME_DIRS:
        seq.dir(sub).mkdir()
    writer = None
    if video:
        writer = cv2.VideoWriter(str(seq.video_path), cv2.VideoWriter.fourcc(*"mp4v"), cfg.fps,
                                 (cfg.width, cfg.height))
        if not writer.isOpened():
            raise OSError(f"OpenCV cannot write {seq.video_path} (no mp4v encoder?)")
    with ThreadPoolExecutor(max_workers=2) as pool:
        pending = []
        for i, fr in enumerate(render_frames(clip, workers=workers)):
            pending += [
                pool.submit(write_image, seq.rgb(i), fr.rgb),
                pool.submit(write_depth, seq.depth(i), fr.depth),
                pool.submit(write_image, seq.semantic(i), fr.semantic),
                pool.submit(write_mask, seq.bsgt(i), fr.bsgt),
                pool.submit(_write_npy, seq.boxes(i), _near_boxes(fr, clip.poses[i])),
            ]
            if writer is not None:
                writer.write(fr.rgb)
            if progress:
                progress(1)
            if len(pending) > 64:
                for f in pending:
                    f.result()
                pending.clear()
        for f in pending:
            f.result()
    if writer is not None:
        writer.release()
    write_kitti_poses(seq.poses_path, clip.poses)
    sc = clip.scenario
    atomic_write_bytes(seq.synth_config_path, (json.dumps({
        "config": cfg.to_dict(), "rig": clip.rig.to_dict(), "sensor": clip.sensor.to_dict(),
        "light": sc.world.look.light, "speed_mps": sc.speed, "pitch_deg": clip.rig.pitch_deg,
        "turns": sc.route.turns, "static_boxes": len(sc.world.static), "agents": len(sc.world.agents),
    }, indent=2) + "\n").encode())
    SequenceMeta(fps=cfg.fps, intrinsics=clip.intrinsics, source=RENDERED, frames=cfg.frames, seed=cfg.seed,
                 extra={"style": cfg.style, "video": SequenceFolder.VIDEO if video else None,
                        "camera_height": clip.rig.height_m, "bs_range": cfg.bs_range}).write(out)
    clip.rig.calibration(cfg.width, cfg.height).write(seq.calibration_path)
    return out


def _near_boxes(fr: Frame, T_wc: np.ndarray, radius: float = 120.0) -> np.ndarray:
    c = 0.5 * (fr.boxes.lo[:, :2] + fr.boxes.hi[:, :2])
    keep = np.linalg.norm(c - T_wc[:2, 3], axis=1) < radius
    return fr.boxes.take(np.where(keep)[0]).to_array()


def _write_npy(path: Path, arr: np.ndarray) -> None:
    buf = io.BytesIO()
    np.save(buf, arr)
    atomic_write_bytes(path, buf.getvalue())
