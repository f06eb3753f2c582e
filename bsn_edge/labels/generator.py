"""T-frame blind-spot labels for one sequence folder."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.card import EARLY_MOUNTING
from bsn_edge.labels.config import LabelConfig
from bsn_edge.labels.monocular import fill_poses, metric_depth_and_poses, seed_poses
from bsn_edge.labels.sources import ClipData, FilesDepth, frame_count
from bsn_edge.labels.sources.base import ClipRejectedError, DepthSource, SegSource
from bsn_edge.labels.sources.registry import make_depth, make_poses, make_seg
from bsn_edge.labels.warp import Cloud, Warper, label_frame
from bsn_edge.model_frame import ModelFrame
from bsn_edge.mounting import REFERENCE_HEIGHT_M
from bsn_edge.sequence import SequenceMeta, read_mask, write_mask
from bsn_edge.sequence.folder import LabelSet, SequenceFolder
from bsn_edge.sequence.frames import read_gray
from bsn_edge.sequence.images import atomic_write_bytes

DEFAULT_CAMERA_HEIGHT = REFERENCE_HEIGHT_M
SEED_WINDOW = 5  # label frames either side: the seed VO's scale drifts too much for one fit per clip
FEATURES_BELOW_FPS = 4.0  # label frames further apart than this rate are matched by features, not tracked


@dataclass(frozen=True)
class Sources:
    """Spec strings of the three sources (see ``bsn_edge.labels.sources``)."""

    depth: str = "files"
    seg: str = "files"
    poses: str = "files"
    calib: str = ""      # a bsn-calibrate file whose intrinsics replace meta.json's


def resample(frames: int, fps: float, rate: float) -> np.ndarray:
    """Indices of the clip's frames at ``rate`` frames/s (nearest frame to each tick)."""
    if rate > fps + 1e-9:
        raise ValueError(f"label rate {rate:g} frames/s is above the clip's {fps:g} frames/s")
    step = fps / rate
    n = int(np.floor((frames - 1) / step + 1e-9)) + 1
    return np.unique(np.rint(np.arange(n) * step).astype(int))


class StaleLabelsError(ValueError):
    """Labels already in the folder were made with other parameters or sources."""


def labels_dir(seq: Path, cfg: LabelConfig) -> Path:
    return SequenceFolder(seq).labels(cfg.name).root


def _params(cfg: LabelConfig, sources: Sources, camera: Intrinsics) -> dict[str, Any]:
    """What makes a label set: every parameter and source (resuming is only right if they match),
    and the camera the labels were computed with (the one training records in the model card)."""
    return {"config": cfg.to_dict(), "sources": dataclasses.asdict(sources), "source_files": _source_files(sources),
            "camera": camera.to_dict()}


def _source_files(sources: Sources) -> dict[str, str]:
    """The sha256 of each file a source names (a model, a trajectory, a camera file): another file at
    the same path makes other labels."""
    named = {"depth": sources.depth, "seg": sources.seg, "poses": sources.poses, "calib": sources.calib}
    out = {}
    for field, spec in named.items():
        path = spec.split(":", 1)[1] if spec.startswith(("onnx:", "bsn:")) else spec
        if path and path not in ("files", "vo", "ground") and Path(path).is_file():
            with open(path, "rb") as f:
                out[field] = hashlib.file_digest(f, "sha256").hexdigest()
    return out


def made_with(labels: LabelSet) -> dict[str, Any]:
    """How a label set was made (``_params``: config, sources, camera); empty when unrecorded."""
    try:
        return json.loads(labels.params_path.read_text())
    except (OSError, json.JSONDecodeError):
        return {}


def label_camera(labels: LabelSet) -> Intrinsics | None:
    """The camera a label set was made with (a ``--calib`` calibration's, else the clip's), or None
    for labels made before it was recorded."""
    cam = made_with(labels).get("camera")
    return Intrinsics(**cam) if cam else None


class _Remembered(SegSource):
    """A segmentation model's classes, computed once per frame: aligning a model's depth, scaling
    it by the ground and labelling each read every label frame's classes."""

    def __init__(self, base: SegSource) -> None:
        self.base, self.name = base, base.name
        self._done: dict[int, np.ndarray] = {}

    def __call__(self, i: int) -> np.ndarray:
        if i not in self._done:
            self._done[i] = self.base(i)
        return self._done[i]

    def forget(self, upto: int) -> None:
        for k in [k for k in self._done if k <= upto]:
            del self._done[k]

    def describe(self) -> dict[str, Any]:
        return self.base.describe()


_DEFAULTS = LabelConfig().to_dict()


def _check_params(labels: LabelSet, params: dict[str, Any], force: bool) -> None:
    """Refuse labels made otherwise (or, with ``force``, remove them); record ``params``."""
    p = labels.params_path
    if p.is_file():
        try:
            old = json.loads(p.read_text())
        except json.JSONDecodeError:
            old = None
        if isinstance(old, dict) and isinstance(old.get("config"), dict):
            # a setting added since the record was written was made at its default
            old["config"] = {**_DEFAULTS, **old["config"]}
            old.setdefault("source_files", {})     # recorded before file digests were: files sources only
        if old != params and not force:
            diff = _differences(old or {}, params)
            raise StaleLabelsError(f"{labels.root} holds labels made with other parameters ({diff}); pass --force "
                                   "to relabel, or keep both by giving this run another --T")
    elif labels.frames() and not force:
        raise StaleLabelsError(f"{labels.root} holds labels with no record of how they were made; pass --force to "
                               "relabel")
    if force and labels.root.is_dir():
        for sub in (labels.BLINDSPOT, labels.VISIBILITY):
            shutil.rmtree(labels.root / sub, ignore_errors=True)
    labels.make_dirs()
    atomic_write_bytes(p, (json.dumps(params, indent=1, sort_keys=True) + "\n").encode(), durable=True)


def _differences(old: dict[str, Any], new: dict[str, Any]) -> str:
    flat = lambda d: {f"{k}.{j}": w for k, v in d.items() if isinstance(v, dict) for j, w in v.items()}  # noqa: E731
    a, b = flat(old), flat(new)
    keys = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
    def name(k: str) -> str:
        section, field = k.split(".", 1)
        return f"{field} file's sha256" if section == "source_files" else field

    def short(v: Any) -> str:
        return f"{v[:12]}..." if isinstance(v, str) and len(v) == 64 else repr(v)

    return ", ".join(f"{name(k)} {short(a.get(k))} -> {short(b.get(k))}" for k in keys[:6]) or "unreadable record"


def _read_done(labels: LabelSet, i: int) -> tuple[np.ndarray, np.ndarray] | None:
    """A finished frame's masks; None if missing, empty or undecodable (then it is labelled again)."""
    if not (labels.blindspot(i).is_file() and labels.visibility(i).is_file()):
        return None
    try:
        return read_mask(labels.blindspot(i)), read_mask(labels.visibility(i))
    except (FileNotFoundError, ValueError):
        return None


def resolve_camera(seq: Path, meta: SequenceMeta, sources: Sources
                    ) -> tuple[SequenceMeta, Calibration | None, ModelFrame | None]:
    """The camera the labels are made in: a camera file (``--calib``, else the clip's own) replaces
    the clip's intrinsics, rescaled to the clip's frame size; with lens distortion, depth and
    segmentation are undistorted first (the returned warp), so the labels are made in the
    undistorted (pinhole) camera the loader warps them from."""
    cam_path = Path(sources.calib) if sources.calib else SequenceFolder(seq).calibration_path
    if not (sources.calib or cam_path.is_file()):
        return meta, None, None
    cal = Calibration.read(cam_path)
    k = cal.intrinsics.scaled(meta.width, meta.height)
    meta = dataclasses.replace(meta, intrinsics=k)
    lens = ModelFrame.undistort_only(k, cal.dist, cal.mounting or EARLY_MOUNTING) if cal.has_distortion else None
    return meta, cal, lens


def open_sources(clip: ClipData, cfg: LabelConfig, sources: Sources, idx: np.ndarray, cal: Calibration | None
                 ) -> tuple[DepthSource, SegSource, np.ndarray, dict[str, Any]]:
    """Depth, segmentation, poses (and what the pose source reports) for the label-rate frames
    ``idx``; raises :class:`ClipRejectedError` when a source cannot be trusted."""
    frames = [int(i) for i in idx]
    seg = make_seg(sources.seg, clip)
    if sources.seg != "files" and sources.depth != "files":
        # the depth source holds every label frame's depth already; their classes cost a quarter of it
        seg = _Remembered(seg)
    if sources.poses == "vo" and sources.depth == "ground":
        return _ground_first(clip, cfg, seg, idx, _camera_height(cfg, cal, clip))
    if sources.poses == "vo" and sources.depth != "files":
        # no metric depth to anchor VO: seed poses, align, ground-scale, re-solve (monocular.py)
        seed, pose_info = seed_poses(clip)
        aligned = make_depth(sources.depth, clip, seed, cfg, frames, window=SEED_WINDOW, seg=seg)
        depth, poses, more = metric_depth_and_poses(clip, aligned, seg, idx, _camera_height(cfg, cal, clip))
        return depth, seg, poses, {"kind": "vo", "metric": True, **pose_info, **more}
    metric = FilesDepth(clip) if sources.depth == "files" else None
    poses, pose_info = make_poses(sources.poses, clip, metric)
    return make_depth(sources.depth, clip, poses, cfg, frames, seg=seg), seg, poses, pose_info


def _camera_height(cfg: LabelConfig, cal: Calibration | None, clip: ClipData) -> float:
    """Metres above the road: ``--camera-height``, the camera file's mounting, meta.json's, the default."""
    return float(cfg.camera_height or (cal.mounting.height_m if cal is not None and cal.mounting else None)
                 or clip.meta.extra.get("camera_height") or DEFAULT_CAMERA_HEIGHT)


def _ground_first(clip: ClipData, cfg: LabelConfig, seg: SegSource, idx: np.ndarray, height: float
                  ) -> tuple[DepthSource, SegSource, np.ndarray, dict[str, Any]]:
    """``--depth ground --poses vo``: the road plane's depth is metric before any pose is known, so
    each step's length comes from it at once (no seed trajectory to scale, and no scale to fit
    afterwards: the steps are measured in the plane's metres). Label frames further
    apart than :data:`FEATURES_BELOW_FPS` allows are matched by features on the classes that do
    not move. A camera file without a mounting gets one from the drive itself when the camera's
    height is stated (``--camera-height`` or meta.json's): the road's normal is square to the
    direction the car travels, which a first pass of the odometry gives."""
    from bsn_edge.labels.sources.ground_depth import GroundDepth, PlaneDepth
    from bsn_edge.labels.vo import travel_direction, visual_odometry
    from bsn_edge.mounting import Mounting
    from bsn_edge.tracks import FeatureMatches

    frames = [int(i) for i in idx]
    K = clip.meta.intrinsics.K
    matches = None
    if cfg.rate < FEATURES_BELOW_FPS:
        matches = FeatureMatches(lambda i: read_gray(clip.seq, i), lambda i: sm.is_static(seg(i)))
    by_k = None if matches is None else (lambda a, b: matches(frames[a], frames[b]))
    grays = [read_gray(clip.seq, i) for i in frames]
    cal = clip.info.get("calibration")
    mounting, found = (cal.mounting if cal is not None else None), "camera file"
    if mounting is None:
        if not (cfg.camera_height or clip.meta.extra.get("camera_height")):
            # pitch and yaw can be found from the drive, the height cannot: it must be stated
            raise ClipRejectedError("depth from the road plane needs the camera's mounting (height, pitch, roll): "
                                    "give a camera file with one (bsn-calibrate --mount), or state the camera's "
                                    "height (--camera-height) to find pitch and yaw from the direction of travel")
        forward = travel_direction(visual_odometry(grays, K, matches=by_k)[0])
        if forward is None:
            raise ClipRejectedError("the camera never moved: no road plane from the drive, and no mounting given")
        mounting, found = Mounting.from_forward(forward, height), "direction of travel"
    plane, _ = GroundDepth.predictor(clip, seg, mounting)
    poses_idx, info = visual_odometry(grays, K, matches=by_k,
                                      depth=lambda k: np.nan_to_num(plane(frames[k]), nan=0.0))
    poses = fill_poses(poses_idx, idx, clip.frames)
    return PlaneDepth(plane, mounting, found), seg, poses, {
        "kind": "vo", "metric": True, "matched_by": "features" if matches else "tracks", **info}


class FrameCache:
    """Each label-rate frame's depth, classes (and grey picture, for the look check) and cloud,
    read (or inferred, for model sources) once: first as a later frame of an earlier label, then
    again as a label frame itself; :meth:`take` hands a label frame over and lets go of what
    comes before it."""

    def __init__(self, seq: Path, idx: np.ndarray, depth: DepthSource, seg: SegSource, poses: np.ndarray,
                 warper: Warper, lens: ModelFrame | None, by_look: bool) -> None:
        self.seq, self.idx, self.depth, self.seg, self.poses = seq, idx, depth, seg, poses
        self.warper, self.lens, self.by_look = warper, lens, by_look
        self._sources: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray | None]] = {}
        self._clouds: dict[int, Cloud] = {}

    def frame(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Depth, classes and grey picture (None without the look check) of label-rate frame ``k``."""
        if k not in self._sources:
            i = int(self.idx[k])
            d, s = self.depth(i), self.seg(i)
            g = read_gray(self.seq, i) if self.by_look else None
            if self.lens is not None:
                d, s = self.lens.depth_to_model(d), self.lens.labels_to_model(s)
                g = None if g is None else self.lens.to_model(g)
            self._sources[k] = (d, s, g)
        return self._sources[k]

    def cloud(self, k: int) -> Cloud:
        if k not in self._clouds:
            d, sem, g = self.frame(k)
            self._clouds[k] = self.warper.cloud(d, sm.is_traversable(sem), self.poses[int(self.idx[k])], g)
        return self._clouds[k]

    def take(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Frame ``k``'s sources, to label it; frames up to it are not needed again."""
        for old in [c for c in self._clouds if c <= k]:
            del self._clouds[old]
        d, s, g = self.frame(k)
        for old in [c for c in self._sources if c <= k]:
            del self._sources[old]
        if isinstance(self.seg, _Remembered):
            self.seg.forget(int(self.idx[k]))
        return d, s, g


def label_sequence(seq: str | Path, cfg: LabelConfig | None = None, sources: Sources | None = None,
                   progress: Callable[[int], None] | None = None,
                   on_total: Callable[[int], None] | None = None, force: bool = False) -> dict[str, Any]:
    """Write labels for ``seq`` under ``labels/T<T>s/`` and return the report (also written as
    ``report.json``). Finished frames are skipped, so a rerun with the same parameters and sources
    resumes; one with others raises :class:`StaleLabelsError` unless ``force`` (relabel). Raises
    :class:`ClipRejectedError` for a clip whose sources cannot be trusted or that is too short
    for ``T`` (the report says why)."""
    cfg = cfg or LabelConfig()
    sources = sources or Sources()
    seq = Path(seq)
    t_start = time.perf_counter()
    meta, cal, lens = resolve_camera(seq, SequenceMeta.read(seq), sources)
    clip = ClipData(seq, meta, frame_count(seq), {"calibration": cal} if cal is not None else {})
    labels = SequenceFolder(seq).labels(cfg.name)
    out = labels.root
    idx = resample(clip.frames, meta.fps, cfg.rate)
    if len(idx) <= cfg.horizon_frames:
        raise ClipRejectedError(f"too short for T = {cfg.horizon_s:g} s: {clip.frames} frames at {meta.fps:g} "
                                f"frames/s give {len(idx)} at {cfg.rate:g} frames/s; a label needs "
                                f"{cfg.horizon_frames + 1} (at least {_min_frames(cfg, meta.fps)} frames of the clip)")
    _check_params(labels, _params(cfg, sources, meta.intrinsics), force)
    report: dict[str, Any] = {
        "sequence": str(seq), "config": cfg.to_dict(), "sources": vars(sources),
        "frames": clip.frames, "fps": meta.fps, "size": [meta.height, meta.width],
    }
    try:
        depth, seg, poses, pose_info = open_sources(clip, cfg, sources, idx, cal)
    except ClipRejectedError as e:
        report.update(status="rejected", reason=str(e))
        _write_report(out, report)
        raise
    report["sources_detail"] = {"depth": depth.describe(), "seg": seg.describe(), "poses": pose_info}

    todo = list(range(max(len(idx) - cfg.horizon_frames, 0)))
    if on_total:
        on_total(len(todo))
    warper = Warper(meta.intrinsics, origin=poses[0, :3, 3])
    cache = FrameCache(seq, idx, depth, seg, poses, warper, lens, cfg.look_tol > 0)
    per_frame = []
    for k in todo:
        per_frame.append(_label_one(labels, cache, warper, idx, k, poses, cfg))
        if progress:
            progress(1)
    elapsed = time.perf_counter() - t_start
    report.update(
        status="ok", label_frames=len(todo), resumed_frames=sum(1 for f in per_frame if f.get("resumed")),
        unlabelled_tail_frames=int(len(idx) - len(todo)), resampled_indices=idx.tolist(),
        min_area_px=cfg.min_area_px(meta.height, meta.width), seconds=round(elapsed, 3), per_frame=per_frame,
    )
    _write_report(out, report)
    return report


def _label_one(labels, cache: FrameCache, warper: Warper, idx: np.ndarray, k: int, poses: np.ndarray,
               cfg: LabelConfig) -> dict[str, Any]:
    """Label the ``k``-th resampled frame (or read it back when an earlier run finished it); its report line."""
    i = int(idx[k])
    done = _read_done(labels, i)
    if done is not None:
        omega, vis = done
        return {"frame": i, "blindspot_px": int(omega.sum()), "visible_px": int(vis.sum()),
                "blindspot_in_v_px": int((omega & vis).sum()), "resumed": True}
    d_t, sem_t, grey_t = cache.take(k)
    lab = label_frame(warper, [cache.cloud(k + j) for j in range(1, cfg.horizon_frames + 1)], d_t,
                      sm.is_traversable(sem_t), sem_t == sm.SKY, poses[i], cfg, grey_t,
                      np.isin(sem_t, sm.ROAD_USERS))
    write_mask(labels.blindspot(i), lab.omega, durable=True)
    write_mask(labels.visibility(i), lab.visibility, durable=True)
    return {"frame": i, "blindspot_px": int(lab.omega.sum()), "visible_px": int(lab.visibility.sum()),
            "blindspot_in_v_px": int((lab.omega & lab.visibility).sum()),
            "warped_px": int(lab.warped.sum()), "removed_by_depth_px": lab.removed_by_depth,
            "removed_by_area_px": lab.removed_by_area, "removed_by_look_px": lab.removed_by_look}


def _min_frames(cfg: LabelConfig, fps: float) -> int:
    """The shortest clip (in its own frames) that gives one label."""
    return int(np.ceil(cfg.horizon_frames * fps / cfg.rate)) + 1


def _write_report(out: Path, report: dict[str, Any]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / LabelSet.REPORT, (json.dumps(report, indent=1) + "\n").encode(), durable=True)
