"""Forward warping of traversable pixels into an earlier frame, and the label of that frame.

For a label frame t and each later frame t+j (j = 1..T) the traversable pixels of t+j
are lifted to 3D with their depth, moved into t's camera and splatted to the nearest
pixel, z-buffered per j so the nearest point wins. Then (paper, Section 3):

    s      = OR_j warped_j                      road seen from some later frame
    omega  = s AND NOT r(t)                     ... that is not visible road in t
    d_a    = mean_j warped depth_j              aggregated depth where warped
    omega &= |d(t) - d_a| >= l_d                points that agree with t's depth are visible
                                                (within one pixel, see ``depth_agrees``)
    omega &= NOT looks alike                    optional (``look_tol``): warped road that looks
                                                like what t shows there is visible too
    omega  = drop components < min area
    V      = sky(t) OR d(t) < L

Speed: each later frame is lifted to world coordinates once and reused by every label
frame that looks at it. A point that shrinks by at least 2^k when seen from t only needs
every 2^k-th pixel in both directions to cover its footprint, so the warp takes each point
from the coarsest grid its shrink allows (``levels``); the shrink is bounded below by the
depth of the point and the distance between the two cameras.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.labels.config import LabelConfig

LEVELS = 4  # pixel grids of 1, 2, 4, 8
LOOK_WINDOW = 7        # pixels: looks are compared as the mean over this square, a patch not a pixel
LOOK_SMOOTH_SIGMA = 1.0  # pixels: pictures are smoothed so that half-pixel warp error is no difference


def smooth_grey(gray: np.ndarray) -> np.ndarray:
    """A grey picture as float32, smoothed so that half-pixel warp error is not a difference."""
    return cv2.GaussianBlur(gray.astype(np.float32), (0, 0), LOOK_SMOOTH_SIGMA)


def window_mean(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Mean of ``values`` over the ``valid`` pixels of each pixel's ``LOOK_WINDOW`` square."""
    count = cv2.blur(valid.astype(np.float32), (LOOK_WINDOW, LOOK_WINDOW))
    total = cv2.blur(np.where(valid, values, 0.0).astype(np.float32), (LOOK_WINDOW, LOOK_WINDOW))
    return total / np.maximum(count, 1e-6)


@dataclass(frozen=True)
class Points:
    """Points of a cloud in world coordinates (float32, relative to the warper's origin), their
    depth in their own frame and, when the cloud was made with its picture, their grey level."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    depth: np.ndarray
    grey: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.depth)

    def select(self, index) -> Points:
        """The points at ``index`` (a mask, a slice or an index array), all fields alike."""
        return Points(self.x[index], self.y[index], self.z[index], self.depth[index],
                      None if self.grey is None else self.grey[index])

    @staticmethod
    def concat(parts: list[Points]) -> Points:
        greys = [p.grey for p in parts if p.grey is not None]
        grey = np.concatenate(greys) if len(greys) == len(parts) else None
        x, y, z, depth = (np.concatenate([getattr(p, f) for p in parts]) for f in ("x", "y", "z", "depth"))
        return Points(x, y, z, depth, grey)


@dataclass(frozen=True)
class Cloud:
    """Traversable points of one frame, grouped by grid level: ``levels[k]`` holds the points on
    the 2^k pixel grid but not the 2^(k+1) one (the last level holds everything on its grid), each
    sorted by depth in their own frame."""

    centre: np.ndarray
    levels: tuple[Points, ...]

    @property
    def size(self) -> int:
        return sum(len(lv) for lv in self.levels)


def _grid_level(height: int, width: int) -> np.ndarray:
    """Per pixel, the largest k < LEVELS with both coordinates divisible by 2^k."""
    v, u = np.mgrid[0:height, 0:width]
    lvl = np.zeros((height, width), np.int8)
    for k in range(1, LEVELS):
        lvl[(u % (1 << k) == 0) & (v % (1 << k) == 0)] = k
    return lvl


class Warper:
    """Builds clouds and labels for one camera (intrinsics fixed for the clip)."""

    def __init__(self, intrinsics: Intrinsics, origin: np.ndarray | None = None) -> None:
        self.intr = intrinsics
        h, w = intrinsics.height, intrinsics.width
        rays = intrinsics.rays()
        self._rx, self._ry = rays[..., 0], rays[..., 1]
        self._level = _grid_level(h, w)
        # world coordinates relative to this origin keep float32 precise for large coordinates
        self.origin = np.zeros(3) if origin is None else np.asarray(origin, np.float64)

    def cloud(self, depth: np.ndarray, traversable: np.ndarray, T_wc: np.ndarray,
              grey: np.ndarray | None = None) -> Cloud:
        """Lift a frame's traversable pixels with valid depth to world coordinates (with their
        grey levels when the frame's ``grey`` picture is given, for ``look_agrees``)."""
        m = traversable & (depth > 0)
        d = depth[m].astype(np.float32)
        x_c, y_c = self._rx[m] * d, self._ry[m] * d
        R = T_wc[:3, :3].astype(np.float32)
        t = (T_wc[:3, 3] - self.origin).astype(np.float32)
        x, y, z = (R[i, 0] * x_c + R[i, 1] * y_c + R[i, 2] * d + t[i] for i in range(3))
        points = Points(x, y, z, d, None if grey is None else smooth_grey(grey)[m])
        lvl = self._level[m]
        levels = []
        for k in range(LEVELS):
            sel = np.flatnonzero(lvl == k if k < LEVELS - 1 else lvl >= k)
            levels.append(points.select(sel[np.argsort(d[sel], kind="stable")]))
        return Cloud(centre=t.astype(np.float64), levels=tuple(levels))

    def _pick(self, cloud: Cloud, baseline: float, margin: float) -> Points:
        """The points of ``cloud`` needed to cover its footprint seen from a camera ``baseline``
        metres away: a point at depth d may shrink to d / (d + margin * baseline)."""
        parts = []
        b = margin * baseline
        for k in range(LEVELS):
            lv = cloud.levels[k]
            # points on grid level k are needed when their shrink is worse than 1 / 2^(k+1),
            # i.e. d >= b / (2^(k+1) - 1); the coarsest level is always needed
            needed_from = b / ((1 << (k + 1)) - 1) if (k < LEVELS - 1 and b > 0) else 0.0
            start = np.searchsorted(lv.depth, needed_from)
            if start < len(lv):
                parts.append(lv.select(slice(start, None)))
        if not parts:
            return cloud.levels[-1].select(slice(0, 0))
        return Points.concat(parts)

    def splat(self, clouds: list[Cloud], T_wc: np.ndarray, margin: float = 0.5
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Warp ``clouds`` into the camera ``T_wc``.

        Returns ``(s, d_a, hits)``: the OR of the warped masks, the mean of the per-cloud
        z-buffered depths (0 where nothing landed) and how many clouds landed on each pixel.
        """
        s, d_a, hits, _ = self.splat_with_grey(clouds, T_wc, margin, False)
        return s, d_a, hits

    def splat_with_grey(self, clouds: list[Cloud], T_wc: np.ndarray, margin: float, want_grey: bool
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """``splat``, and with ``want_grey`` the grey level of each cloud's nearest point per
        pixel, ``[len(clouds), H, W]`` (NaN where the cloud did not land; None without)."""
        h, w = self.intr.height, self.intr.width
        n_px = h * w
        R_cw = T_wc[:3, :3].T.astype(np.float32)
        C = (T_wc[:3, 3] - self.origin).astype(np.float32)
        keys, depths, greys = [], [], []
        for j, cl in enumerate(clouds):
            base = float(np.linalg.norm(cl.centre - C))
            pts = self._pick(cl, base, margin)
            if want_grey and pts.grey is None:
                raise ValueError("a cloud made without its picture cannot be compared by look")
            x, y, z = pts.x - C[0], pts.y - C[1], pts.z - C[2]
            zc = R_cw[2, 0] * x + R_cw[2, 1] * y + R_cw[2, 2] * z
            ok = zc > 0.05
            x, y, z, zc = x[ok], y[ok], z[ok], zc[ok]
            grey = pts.grey[ok] if want_grey and pts.grey is not None else None
            inv = 1.0 / zc
            u = (self.intr.fx * (R_cw[0, 0] * x + R_cw[0, 1] * y + R_cw[0, 2] * z) * inv + self.intr.cx)
            v = (self.intr.fy * (R_cw[1, 0] * x + R_cw[1, 1] * y + R_cw[1, 2] * z) * inv + self.intr.cy)
            ui = np.rint(u).astype(np.int32)
            vi = np.rint(v).astype(np.int32)
            ok = (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
            keys.append(j * n_px + vi[ok] * w + ui[ok])
            depths.append(zc[ok])
            if grey is not None:
                greys.append(grey[ok])
        zbuf: np.ndarray = np.full(len(clouds) * n_px, np.inf, np.float32)
        gbuf: np.ndarray | None = None
        if keys:
            all_keys, all_depths = np.concatenate(keys), np.concatenate(depths)
            np.minimum.at(zbuf, all_keys, all_depths)
            if want_grey:
                gbuf = np.full(len(clouds) * n_px, np.nan, np.float32)
                won = zbuf[all_keys] == all_depths        # the nearest point of its cloud on its pixel
                gbuf[all_keys[won]] = np.concatenate(greys)[won]
                gbuf = gbuf.reshape(len(clouds), h, w)
        elif want_grey:
            gbuf = np.full((len(clouds), h, w), np.nan, np.float32)
        zbuf = zbuf.reshape(len(clouds), h, w)
        landed = np.isfinite(zbuf)
        hits = landed.sum(axis=0)
        total = np.where(landed, zbuf, 0.0).sum(axis=0)
        d_a = np.divide(total, hits, out=np.zeros((h, w), np.float32), where=hits > 0)
        return hits > 0, d_a.astype(np.float32), hits, gbuf


def remove_small_components(mask: np.ndarray, min_area: int) -> np.ndarray:
    """Drop 8-connected components of ``mask`` smaller than ``min_area`` pixels."""
    if min_area <= 1 or not mask.any():
        return mask
    _, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_area
    keep[0] = False
    return keep[lab]


@dataclass(frozen=True)
class FrameLabel:
    """Label of one frame and the intermediate masks (for reports and tests)."""

    omega: np.ndarray        # T-frame blind spots
    visibility: np.ndarray   # V
    warped: np.ndarray       # s
    aggregated_depth: np.ndarray  # d_a
    removed_by_depth: int
    removed_by_area: int
    removed_by_look: int = 0


def depth_agrees(depth: np.ndarray, d_a: np.ndarray, depth_tol: float) -> np.ndarray:
    """``|d(t) - d_a| < l_d`` up to the warp's one-pixel localisation: a splatted point lands
    within half a pixel of its true position, so it agrees if some depth of the 3x3
    neighbourhood is within ``l_d`` of it. Without this, road far ahead, where one pixel row
    spans tens of metres, never agrees with itself."""
    known = np.where(depth > 0, depth, np.float32(np.nan)).astype(np.float32)
    k = np.ones((3, 3), np.uint8)
    lo = cv2.erode(np.nan_to_num(known, nan=np.inf), k)
    hi = cv2.dilate(np.nan_to_num(known, nan=-np.inf), k)
    return (d_a > lo - depth_tol) & (d_a < hi + depth_tol)


def look_agrees(grey: np.ndarray, warped_grey: np.ndarray, look_tol: float) -> np.ndarray:
    """Pixels where some later frame's road, warped here, looks like what this frame shows: the
    window mean of ``|grey - warped|`` over the pixels it landed on is under ``look_tol`` grey
    levels. That road is seen here, whatever this frame's segmentation or depth says.
    ``warped_grey`` is ``[n, H, W]`` (NaN where a frame's road did not land)."""
    here = smooth_grey(grey)
    seen = np.zeros(here.shape, bool)
    for g in warped_grey:
        landed = np.isfinite(g)
        if landed.any():
            diff = np.where(landed, np.abs(here - np.nan_to_num(g)), 0.0).astype(np.float32)
            seen |= landed & (window_mean(diff, landed) < look_tol)
    return seen


def label_frame(warper: Warper, clouds: list[Cloud], depth: np.ndarray, traversable: np.ndarray,
                sky: np.ndarray, T_wc: np.ndarray, cfg: LabelConfig, grey: np.ndarray | None = None,
                users: np.ndarray | None = None) -> FrameLabel:
    """T-frame blind spots and the visibility mask of one frame from the clouds of later frames,
    with ``cfg``'s tolerances (``depth_tol``, ``vis_range``, ``min_area`` at this frame's size,
    ``shrink_margin``); with ``look_tol`` > 0 (clouds made with their pictures, this frame's
    ``grey``), warped road that looks like this frame's picture is visible too (``look_agrees``).
    With ``users_unknown``, the pixels of road users (``users``) left without label are out of V."""
    by_look = cfg.look_tol > 0
    if by_look and grey is None:
        raise ValueError("comparing by look needs the label frame's grey picture")
    s, d_a, _, warped_grey = warper.splat_with_grey(clouds, T_wc, cfg.shrink_margin, by_look)
    omega = s & ~traversable & ~sky
    agree = omega & depth_agrees(depth, d_a, cfg.depth_tol) if cfg.depth_tol > 0 else np.zeros_like(omega)
    omega &= ~agree
    looks = omega & look_agrees(grey, warped_grey, cfg.look_tol) if grey is not None and warped_grey is not None \
        else np.zeros_like(omega)
    omega &= ~looks
    kept = remove_small_components(omega, cfg.min_area_px(*depth.shape))
    vis = sky | ((depth > 0) & (depth < cfg.vis_range))
    if cfg.users_unknown:
        if users is None:
            raise ValueError("leaving road users out of V needs their pixels")
        vis &= kept | ~users
    return FrameLabel(kept, vis, s, d_a, int(agree.sum()), int(omega.sum() - kept.sum()), int(looks.sum()))
