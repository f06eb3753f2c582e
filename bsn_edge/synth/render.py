"""Ray-cast rendering of the synthetic world: RGB, exact depth, semantics and true blind spots.

Every pixel's ray is intersected with the ground plane (z = 0) analytically and
with the boxes whose screen footprint covers it. Depth is the z-depth in the
camera frame (the ray's parameter, since rays have unit z).

True blind spots (BS-GT): pixels whose first hit is an object and whose ray,
continued through that object, reaches traversable ground (road or sidewalk)
that lies within ``bs_range`` metres of the camera (horizontal distance) and is
not under a box standing on the ground.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.camera import Intrinsics
from bsn_edge.synth.boxes import Boxes
from bsn_edge.synth.light import GroundMaps
from bsn_edge.synth.shading import Shader
from bsn_edge.synth.world import World

SPHERE_MARGIN_M = 0.05   # frustum culling keeps a box whose bounding sphere is within this of the view
_EDGES = np.array([(a, b) for a in range(8) for b in range(a + 1, 8)
                   if bin(a ^ b).count("1") == 1])  # the 12 edges of a box, corner-index pairs


@dataclass(frozen=True)
class Trace:
    """Geometry of one frame before shading (all ``[H, W]``)."""

    t: np.ndarray          # depth of the first hit; inf where nothing is hit within range
    box: np.ndarray        # index into the frame's boxes of the first hit, -1 for ground or sky
    ground: np.ndarray     # the ray meets the ground within range
    gx: np.ndarray         # where (nan where it does not)
    gy: np.ndarray
    tg: np.ndarray         # depth of that ground point
    under: np.ndarray      # that ground point lies under a grounded box
    dirs: tuple[np.ndarray, np.ndarray, np.ndarray]  # world ray directions


@dataclass(frozen=True)
class Frame:
    """One rendered frame."""

    rgb: np.ndarray        # [H, W, 3] uint8 BGR, or float32 scene radiance when rendered with radiance=True
    depth: np.ndarray      # [H, W] float32 metres, 0 = sky / no depth
    semantic: np.ndarray   # [H, W] uint8 trainIds
    bsgt: np.ndarray       # [H, W] bool, true blind spots
    boxes: Boxes           # the boxes that existed at this instant


class Renderer:
    """Renders a :class:`World` through a pinhole camera."""

    def __init__(self, intrinsics: Intrinsics, far: float = 250.0, bs_range: float = 50.0,
                 near: float = 0.05) -> None:
        if not 0 < near < far:
            raise ValueError(f"need 0 < near < far, got near={near} far={far}")
        self.intr = intrinsics
        self.far, self.near, self.bs_range = float(far), float(near), float(bs_range)
        rays = intrinsics.rays()
        self._rx = np.ascontiguousarray(rays[..., 0])
        self._ry = np.ascontiguousarray(rays[..., 1])
        # ``far`` bounds the z-depth; the farthest point in view is that far along the widest ray
        self._reach = self.far * float(np.sqrt(1.0 + rays[..., 0] ** 2 + rays[..., 1] ** 2).max())
        # the view frustum's planes in the camera frame (unit normals pointing in, offsets): near,
        # then the picture's left, right, top and bottom edges
        k = intrinsics
        sides = np.array([[k.fx, 0.0, k.cx], [-k.fx, 0.0, k.width - k.cx],
                          [0.0, k.fy, k.cy], [0.0, -k.fy, k.height - k.cy]])
        self._planes = np.vstack([[0.0, 0.0, 1.0], sides / np.linalg.norm(sides, axis=1, keepdims=True)])
        self._plane_offsets = np.array([self.near, 0.0, 0.0, 0.0, 0.0])
        self.shader = Shader(intrinsics.height, intrinsics.width)
        self.shader.set_rays(rays)
        self._maps: GroundMaps | None = None
        self._maps_world: World | None = None    # the world the maps were made for

    # -- geometry ---------------------------------------------------------------------------
    def _world_dirs(self, R: np.ndarray):
        R = R.astype(np.float32)
        return tuple(R[i, 0] * self._rx + R[i, 1] * self._ry + R[i, 2] for i in range(3))

    def _screen_boxes(self, boxes: Boxes, T_wc: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Boxes in view: indices, pixel rectangles ``[n, 4]`` (u0, v0, u1, v1) and nearest depth."""
        if not len(boxes):
            return np.zeros(0, np.intp), np.zeros((0, 4), np.intp), np.zeros(0)
        C = T_wc[:3, 3]
        centre = 0.5 * (boxes.lo + boxes.hi)
        radius = 0.5 * np.linalg.norm(boxes.hi - boxes.lo, axis=1)
        cand = np.where(np.linalg.norm(centre[:, :2] - C[:2], axis=1) - radius < self._reach)[0]
        R_cw = T_wc[:3, :3].T
        # a box whose bounding sphere lies wholly outside one plane of the frustum covers no pixel
        # and no ground point in view: its corners are not needed (the margin absorbs rounding)
        dist = (centre[cand] - C) @ R_cw.T @ self._planes.T - self._plane_offsets
        cand = cand[(dist > -(radius[cand, None] + SPHERE_MARGIN_M)).all(axis=1)]
        if not len(cand):
            return cand, np.zeros((0, 4), np.intp), np.zeros(0)
        corners = (boxes.take(cand).corners() - C) @ R_cw.T          # [n, 8, 3] camera frame
        z = corners[..., 2]
        front = z >= self.near
        in_view = front.any(axis=1)
        corners, z, front, cand = corners[in_view], z[in_view], front[in_view], cand[in_view]
        # clip the box's edges at the near plane: crossing points join the corners in front
        p0, p1 = corners[:, _EDGES[:, 0]], corners[:, _EDGES[:, 1]]
        z0, z1 = z[:, _EDGES[:, 0]], z[:, _EDGES[:, 1]]
        cross = (z0 - self.near) * (z1 - self.near) < 0
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (self.near - z0) / (z1 - z0)
            pc = p0 + s[..., None] * (p1 - p0)
        pts = np.concatenate([corners, pc], axis=1)
        valid = np.concatenate([front, cross], axis=1)
        zmin = np.where(valid, pts[..., 2], np.inf).min(axis=1)
        zz = np.where(valid, pts[..., 2], 1.0)
        u = np.where(valid, self.intr.fx * pts[..., 0] / zz + self.intr.cx, np.nan)
        v = np.where(valid, self.intr.fy * pts[..., 1] / zz + self.intr.cy, np.nan)
        rect = np.stack([np.nanmin(u, 1), np.nanmin(v, 1), np.nanmax(u, 1), np.nanmax(v, 1)], axis=1)
        rect = np.floor(rect).astype(np.int64)
        rect[:, 2:] += 2
        rect[:, [0, 2]] = np.clip(rect[:, [0, 2]], 0, self.intr.width)
        rect[:, [1, 3]] = np.clip(rect[:, [1, 3]], 0, self.intr.height)
        ok = (rect[:, 2] > rect[:, 0]) & (rect[:, 3] > rect[:, 1])
        return cand[ok], rect[ok], zmin[ok]

    def trace(self, boxes: Boxes, T_wc: np.ndarray) -> Trace:
        """Intersect every pixel's ray with the ground and the boxes."""
        C = T_wc[:3, 3].astype(np.float64)
        dx, dy, dz = self._world_dirs(T_wc[:3, :3])
        with np.errstate(divide="ignore", invalid="ignore"):
            tg = np.where(dz < 0, np.float32(-C[2]) / dz, np.float32(np.inf)).astype(np.float32)
            ground = tg < self.far
            gx = np.where(ground, np.float32(C[0]) + tg * dx, np.float32(np.nan))
            gy = np.where(ground, np.float32(C[1]) + tg * dy, np.float32(np.nan))
            inv = (np.float32(1.0) / dx, np.float32(1.0) / dy, np.float32(1.0) / dz)
        # nothing is seen beyond ``far`` (the depth format's range): a ray that misses the ground
        # only takes a box nearer than that
        t = np.where(ground, tg, np.float32(self.far))
        box = np.full(t.shape, -1, np.int32)
        under = np.zeros(t.shape, bool)
        idx, rects, zmin = self._screen_boxes(boxes, T_wc)
        # Front to back, so a box whose screen rectangle is already covered by nearer surfaces is
        # skipped. Its footprint still matters where it lies within range: a ray that passes
        # through a hidden box and lands under it does not see traversable ground.
        order = np.argsort(zmin, kind="stable")
        idx, rects, zmin = idx[order], rects[order], zmin[order].astype(np.float32)
        lo = (boxes.lo[idx] - C).astype(np.float32)
        hi = (boxes.hi[idx] - C).astype(np.float32)
        gap = np.maximum(np.maximum(lo[:, :2], -hi[:, :2]), 0.0)
        footprint_matters = boxes.grounded[idx] & (np.hypot(gap[:, 0], gap[:, 1]) <= self.bs_range)
        near = np.float32(self.near)
        # the loop reads per-box values as Python numbers (float32 values, exactly): reading numpy
        # scalars one by one costs more than the work on small boxes
        rect_l, zmin_l, lo_l, hi_l = rects.tolist(), zmin.tolist(), lo.tolist(), hi.tolist()
        with np.errstate(invalid="ignore", over="ignore"):
            for k in range(len(idx)):
                u0, v0, u1, v1 = rect_l[k]
                sl = (slice(v0, v1), slice(u0, u1))
                tb = t[sl]
                if tb.max() > zmin_l[k]:
                    lo_k, hi_k = lo_l[k], hi_l[k]
                    p, q = lo_k[0] * inv[0][sl], hi_k[0] * inv[0][sl]
                    tn, tf = np.minimum(p, q), np.maximum(p, q)
                    for a in (1, 2):
                        ia = inv[a][sl]
                        p, q = lo_k[a] * ia, hi_k[a] * ia
                        np.maximum(tn, np.minimum(p, q), out=tn)
                        np.minimum(tf, np.maximum(p, q), out=tf)
                    hit = (tn <= tf) & (tn > near) & (tn < tb)
                    np.copyto(tb, tn, where=hit)
                    np.copyto(box[sl], np.int32(idx[k]), where=hit)
                if footprint_matters[k]:
                    gxs, gys = gx[sl], gy[sl]
                    ub = under[sl]
                    ub |= (gxs >= lo[k, 0] + C[0]) & (gxs <= hi[k, 0] + C[0]) & \
                          (gys >= lo[k, 1] + C[1]) & (gys <= hi[k, 1] + C[1])
        return Trace(t, box, ground, gx, gy, tg, under, (dx, dy, dz))

    # -- frame ------------------------------------------------------------------------------
    def render(self, world: World, T_wc: np.ndarray, time_s: float = 0.0,
               frame_index: int = 0, radiance: bool = False) -> Frame:
        """Render ``world`` at time ``time_s`` from the camera pose ``T_wc``.

        ``rgb`` is 8-bit (radiance x 255, no sensor effects) unless ``radiance``, when it is the
        float scene radiance for a sensor model to develop.
        """
        boxes = world.boxes_at(time_s)
        tr = self.trace(boxes, T_wc)
        obj = tr.box >= 0
        ground_cls = np.full(tr.t.shape, sm.SKY, np.uint8)
        marking = np.zeros(tr.t.shape, bool)
        curb = np.zeros(tr.t.shape, bool)
        g = tr.ground
        ground_cls[g], marking[g], curb[g] = world.layout.ground(tr.gx[g], tr.gy[g])
        semantic = ground_cls.copy()
        semantic[obj] = boxes.cls[tr.box[obj]]
        hit = obj | g
        depth = np.where(hit, tr.t, np.float32(0.0)).astype(np.float32)
        C = T_wc[:3, 3]
        dist = np.hypot(tr.gx - np.float32(C[0]), tr.gy - np.float32(C[1]))
        with np.errstate(invalid="ignore"):
            in_range = dist <= self.bs_range
        bsgt = obj & g & sm.is_traversable(ground_cls) & ~tr.under & in_range
        maps = self._maps
        if maps is None or self._maps_world is not world:
            maps = self._maps = GroundMaps(world.look.sun, world.look.night)
            self._maps_world = world
        ns = len(world.static)
        fwd = T_wc[:2, 2] / max(float(np.linalg.norm(T_wc[:2, 2])), 1e-6)
        maps.update(world.static, boxes.take(np.arange(ns, len(boxes))), C[:2], fwd)
        rgb = self.shader.shade(world, boxes, tr, ground_cls, marking, curb, obj, T_wc, maps)
        if not radiance:
            rgb = np.clip(rgb * np.float32(255.0) + 0.5, 0, 255).astype(np.uint8)
        return Frame(rgb, depth, semantic, bsgt, boxes)
