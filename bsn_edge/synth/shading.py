"""Appearance of the synthetic world: surfaces, sun and sky light, shadows, night lights, fog.

The shader returns scene radiance (float, a white surface in full sun is about 1); the clip's
:mod:`sensor <bsn_edge.synth.sensor>` turns it into 8-bit pixels. Shading runs once per frame
over compact arrays of ground, object and sky pixels, so its cost does not grow with the number
of boxes; cast shadows come from :class:`~bsn_edge.synth.light.GroundMaps`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.synth.boxes import (
    FACING_AXES,
    KIND_BARRIER,
    KIND_BUILDING,
    KIND_CABIN,
    KIND_CROWN,
    KIND_FENCE,
    KIND_HEAD,
    KIND_HEDGE,
    KIND_HILL,
    KIND_POLE,
    KIND_VEHICLE,
    KIND_WALL,
    KIND_WHEEL,
    Boxes,
)

if TYPE_CHECKING:
    from bsn_edge.synth.light import GroundMaps
    from bsn_edge.synth.render import Trace
    from bsn_edge.synth.world import World

TEX = 256            # texture tile size (texels); a power of two so wrapping is a mask
GROUND_TEXEL = 0.08  # metres per texel of the fine ground texture
COARSE_TEXEL = 1.6   # metres per texel of the large-scale stains
CLOUD_TEXEL = 40.0   # metres per texel of the cloud layer
CLOUD_HEIGHT = 600.0

GLASS = np.array([0.10, 0.10, 0.11], np.float32)
WINDOW = np.array([0.22, 0.20, 0.18], np.float32)
TYRE = np.array([0.05, 0.05, 0.05], np.float32)
RIM = np.array([0.50, 0.52, 0.54], np.float32)
ROOF = np.array([(0.33, 0.33, 0.35), (0.20, 0.22, 0.35), (0.28, 0.28, 0.28), (0.45, 0.45, 0.46)], np.float32)
HEADLAMP = np.array([0.88, 0.90, 0.92], np.float32)
TAILLAMP = np.array([0.10, 0.10, 0.70], np.float32)
PLATE = np.array([(0.92, 0.92, 0.92), (0.20, 0.85, 0.95)], np.float32)
BUMPER = np.array([0.12, 0.12, 0.12], np.float32)
HAIR = np.array([(0.05, 0.06, 0.08), (0.10, 0.20, 0.35), (0.45, 0.60, 0.75)], np.float32)
SODIUM = np.array([0.45, 0.78, 1.0], np.float32)       # street-light colour, BGR
LAMP_GLOW = np.array([2.2, 2.3, 2.4], np.float32)      # emitted radiance of lit headlamps
TAIL_GLOW = np.array([0.15, 0.15, 1.2], np.float32)
WINDOW_GLOW = np.array([0.35, 0.65, 0.9], np.float32)


def periodic_noise(rng: np.random.Generator, size: int, cutoff: float) -> np.ndarray:
    """Tileable smooth noise in [-1, 1]: white noise low-passed in the Fourier domain."""
    white = rng.standard_normal((size, size))
    f = np.fft.rfft2(white)
    ky = np.fft.fftfreq(size)[:, None]
    kx = np.fft.rfftfreq(size)[None, :]
    f *= np.exp(-(kx**2 + ky**2) / (2 * cutoff**2))
    n = np.fft.irfft2(f, s=(size, size))
    n /= np.abs(n).max() + 1e-9
    return n.astype(np.float32)


def _sample(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    # truncation, not floor: a texel's shift across zero does not show in a random texture
    iu = u.astype(np.int32) & (TEX - 1)
    iv = v.astype(np.int32) & (TEX - 1)
    return tex[iv, iu]


def _hash(track: np.ndarray, salt: int) -> np.ndarray:
    """A per-object pseudo-random integer in [0, 1000), stable across frames."""
    h = (track.astype(np.int64) * 2654435761 + salt * 40503) & 0xFFFFFFFF
    return (h >> 7) % 1000


class Shader:
    """Turns a :class:`Trace` into scene radiance."""

    def __init__(self, height: int, width: int, seed: int = 7) -> None:
        rng = np.random.default_rng(seed)
        self.fine = periodic_noise(rng, TEX, 0.25)
        self.coarse = periodic_noise(rng, TEX, 0.03)
        self.mid = periodic_noise(rng, TEX, 0.08)
        self.cloud = periodic_noise(rng, TEX, 0.05)
        self._shape = (height, width)
        self._ray_norm: np.ndarray | None = None

    def set_rays(self, rays: np.ndarray) -> None:
        """Camera-frame rays ``[H, W, 3]``; their lengths normalise directions."""
        self._ray_norm = np.sqrt((rays**2).sum(axis=-1)).astype(np.float32)

    def shade(self, world: World, boxes: Boxes, tr: Trace, ground_cls: np.ndarray,
              marking: np.ndarray, curb: np.ndarray, obj: np.ndarray, T_wc: np.ndarray,
              maps: GroundMaps) -> np.ndarray:
        look = world.look
        h, w = self._shape
        out = np.empty((h * w, 3), np.float32)
        sun = np.asarray(look.sun, np.float32)
        si = np.flatnonzero(~(obj | tr.ground))
        if len(si):
            out[si] = self._sky(look, tr, si, T_wc)
        gi = np.flatnonzero(tr.ground & ~obj)
        if len(gi):
            out[gi] = self._ground(look, tr, ground_cls, marking, curb, gi, sun, maps)
        oi = np.flatnonzero(obj)
        if len(oi):
            out[oi] = self._objects(look, boxes, tr, T_wc, oi, sun, maps)
        # fog over the whole frame at once: the sky keeps its own colour
        fog = np.exp(np.minimum(tr.t, np.float32(1e4)) * np.float32(-1.0 / look.fog_distance))
        fog[~(obj | tr.ground)] = 1.0
        img = out.reshape(h, w, 3)
        haze = np.asarray(look.haze, np.float32)
        img -= haze
        img *= fog[..., None]
        img += haze
        return img

    # -- sky ----------------------------------------------------------------------------------
    def _sky(self, look, tr, si, T_wc) -> np.ndarray:
        if self._ray_norm is None:
            raise RuntimeError("the shader has no camera rays: set_rays first")
        n = self._ray_norm.reshape(-1)[si]
        dx, dy, dz = (tr.dirs[a].reshape(-1)[si] / n for a in range(3))
        mix = np.clip(dz * 2.5, 0.0, 1.0)[:, None]
        hor = np.asarray(look.sky_horizon, np.float32)
        sky = hor + mix * (np.asarray(look.sky_zenith, np.float32) - hor)
        if look.clouds > 0:
            up = np.maximum(dz, 0.03)
            C = T_wc[:3, 3]
            cu = (C[0] + dx / up * CLOUD_HEIGHT) / CLOUD_TEXEL
            cv_ = (C[1] + dy / up * CLOUD_HEIGHT) / CLOUD_TEXEL
            c = _sample(self.cloud, cu, cv_) * 0.5 + 0.5 + 0.15 * _sample(self.mid, cu * 3, cv_ * 3)
            cover = np.clip((c - (1.0 - look.clouds)) * 4.0, 0.0, 1.0) * np.clip(dz * 8.0, 0, 1)
            bright = 0.08 if look.night else (0.93 if look.light != "overcast" else 0.8)
            cloud = np.float32(bright) * (0.85 + 0.15 * c)[:, None] * np.asarray(look.sun_color, np.float32)
            sky = sky * (1 - cover[:, None]) + cloud * cover[:, None]
        return sky

    # -- ground -------------------------------------------------------------------------------
    def _ground(self, look, tr, ground_cls, marking, curb, gi, sun, maps) -> np.ndarray:
        cls = ground_cls.reshape(-1)[gi]
        gx, gy = tr.gx.reshape(-1)[gi], tr.gy.reshape(-1)[gi]
        t = tr.t.reshape(-1)[gi]
        lut = np.zeros((256, 3), np.float32)
        lut[sm.ROAD], lut[sm.SIDEWALK], lut[sm.TERRAIN] = look.road, look.sidewalk, look.terrain
        amp = np.zeros(256, np.float32)
        amp[sm.ROAD], amp[sm.SIDEWALK], amp[sm.TERRAIN] = 0.12, 0.06, 0.35
        base = lut[cls]
        base[curb.reshape(-1)[gi]] *= 1.15
        road = cls == sm.ROAD
        mid = _sample(self.mid, gx / 0.5, gy / 0.5)
        if road.any():
            # repaired patches and cracks, more of both on worn roads
            patch = _sample(self.coarse, gx[road] / 0.35, gy[road] / 0.35)
            f = np.where(patch > 0.75 - 0.35 * look.wear, 0.82, np.where(patch < -0.8 + 0.2 * look.wear, 1.12, 1.0))
            crack = np.abs(_sample(self.mid, gx[road] / 0.09, gy[road] / 0.09)) < 0.02 * look.wear
            base[road] *= np.where(crack, 0.55, f)[:, None].astype(np.float32)
        mk = marking.reshape(-1)[gi]
        if mk.any():
            keep = np.clip(1.0 - look.wear * (0.6 + 0.5 * mid[mk]), 0.1, 1.0)[:, None]
            base[mk] = np.asarray(look.marking, np.float32) * keep + base[mk] * (1 - keep)
        side = cls == sm.SIDEWALK
        joints = side & ((np.mod(gx, 0.6) < 0.04) | (np.mod(gy, 0.6) < 0.04))
        base[joints] *= 0.85
        grass = cls == sm.TERRAIN
        if grass.any():
            base[grass] *= (0.85 + 0.25 * mid[grass])[:, None]
        fade = np.clip(1.0 - t / 60.0, 0.15, 1.0)
        fine = _sample(self.fine, gx / GROUND_TEXEL, gy / GROUND_TEXEL) * amp[cls] * fade
        coarse = _sample(self.coarse, gx / COARSE_TEXEL, gy / COARSE_TEXEL) * 0.07
        lit, ao, lamp = maps.ground_light(gx, gy)
        direct = np.float32(look.sun_strength * max(float(sun[2]), 0.0)) * lit
        light = (np.float32(look.ambient) * (1.0 - 0.75 * ao))[:, None] + \
            direct[:, None] * np.asarray(look.sun_color, np.float32)
        if lamp is not None:
            light = light + (1.3 * lamp)[:, None] * SODIUM
        return base * (1.0 + fine + coarse)[:, None] * light

    # -- objects ------------------------------------------------------------------------------
    def _objects(self, look, boxes: Boxes, tr, T_wc, oi, sun, maps) -> np.ndarray:
        C = T_wc[:3, 3].astype(np.float32)
        bi = tr.box.reshape(-1)[oi]
        t = tr.t.reshape(-1)[oi]
        d = [tr.dirs[a].reshape(-1)[oi] for a in range(3)]
        px, py, pz = (C[a] + t * d[a] for a in range(3))
        # per-box columns first (few boxes), then 1-D gathers per pixel
        lo_b = boxes.lo.astype(np.float32)
        size_b = boxes.hi.astype(np.float32) - lo_b
        mid_b = lo_b + 0.5 * size_b
        inv_half_b = 2.0 / size_b
        rx = (px - mid_b[:, 0][bi]) * inv_half_b[:, 0][bi]
        ry = (py - mid_b[:, 1][bi]) * inv_half_b[:, 1][bi]
        z = pz - lo_b[:, 2][bi]
        height = size_b[:, 2][bi]
        rz = np.maximum(2.0 * z / height - 1.0, 0.0)      # bottoms are never lit
        ax, ay = np.abs(rx), np.abs(ry)
        on_x = (ax >= ay) & (ax >= rz)
        on_y = ~on_x & (ay >= rz)
        side_face = on_x | on_y
        nx = np.where(on_x, np.sign(rx), np.float32(0.0))
        ny = np.where(on_y, np.sign(ry), np.float32(0.0))
        nz = (~side_face).astype(np.float32)
        ndotl = nx * sun[0] + ny * sun[1] + nz * sun[2]
        u = np.where(on_x, py - lo_b[:, 1][bi], px - lo_b[:, 0][bi])     # across the face, metres
        ulen = np.where(on_x, size_b[:, 1][bi], size_b[:, 0][bi])
        kind = boxes.kind[bi]
        track = boxes.track[bi]
        col = boxes.color[bi]
        glow = np.zeros_like(col) if look.night else None
        spec = np.zeros(len(oi), np.float32)          # share of mirror reflection
        tex = _sample(self.fine, u * 20.0, z * 20.0)
        self._paint(look, boxes, bi, kind, track, on_x, on_y, side_face, nx, ny, u, ulen, z, height, tex, col, glow,
                    spec)

        shade = 1.0 + 0.04 * tex
        lit = maps.object_lit(px, py, pz, track) if look.sun_strength > 0.15 else np.float32(1.0)
        sky_part = np.float32(look.ambient) * (0.7 + 0.3 * nz)
        direct = np.float32(look.sun_strength) * np.maximum(ndotl, 0.0) * lit
        light = (sky_part * shade)[:, None] + (direct * shade)[:, None] * np.asarray(look.sun_color, np.float32)
        if look.night:
            light += (0.8 * maps.object_light(px, py) * (z < 3.0))[:, None] * SODIUM
        rad = col * light
        k = np.flatnonzero(spec)
        if len(k):
            rad[k] += _mirror(look, sun, [d[a][k] for a in range(3)], nx[k], ny[k], nz[k], spec[k],
                              np.asarray(lit)[k] if np.ndim(lit) else lit)
        return rad if glow is None else rad + glow

    def _paint(self, look, boxes: Boxes, bi, kind, track, on_x, on_y, side_face, nx, ny, u, ulen, z, height, tex,
               col, glow, spec) -> None:
        """Each kind's colour pattern, into ``col`` (and the night's ``glow``, the mirror share ``spec``)."""
        kind_of = np.bincount(kind, minlength=16)

        if kind_of[KIND_BUILDING]:
            k = np.flatnonzero(kind == KIND_BUILDING)
            self._building(look, k, track[k], _hash(boxes.track, 1)[bi[k]], u[k], z[k], side_face[k], tex[k], col,
                           glow, spec)
        if kind_of[KIND_VEHICLE] or kind_of[KIND_CABIN]:
            k = np.flatnonzero((kind == KIND_VEHICLE) | (kind == KIND_CABIN))
            self._vehicle(boxes, bi[k], kind[k], on_x[k], on_y[k], nx[k], ny[k], u[k], ulen[k], z[k], height[k],
                          track[k], k, col, glow, spec, look)
        if kind_of[KIND_WHEEL]:
            k = np.flatnonzero(kind == KIND_WHEEL)
            r = height[k] / 2
            hub = ((u[k] - ulen[k] / 2) ** 2 + (z[k] - r) ** 2 < (0.55 * r) ** 2) & \
                side_face[k] & (np.abs(ulen[k] - height[k]) < 0.05)
            col[k] = np.where(hub[:, None], RIM, TYRE)
        if kind_of[KIND_HEAD]:
            k = np.flatnonzero((kind == KIND_HEAD) & (z > 0.55 * height))
            col[k] = HAIR[_hash(track[k], 3) % len(HAIR)]
        if kind_of[KIND_CROWN] or kind_of[KIND_HEDGE] or kind_of[KIND_HILL]:
            k = np.flatnonzero((kind == KIND_CROWN) | (kind == KIND_HEDGE) | (kind == KIND_HILL))
            scale = np.where(kind[k] == KIND_HILL, np.float32(2.5), np.float32(0.12))
            clump = _sample(self.mid, u[k] / scale + track[k], z[k] / scale)
            speck = _sample(self.fine, u[k] / (scale * 0.3), z[k] / (scale * 0.3))
            col[k] *= (0.7 + 0.4 * clump + 0.15 * speck)[:, None]
        if kind_of[KIND_FENCE]:
            k = np.flatnonzero(kind == KIND_FENCE)
            col[k] *= (1.0 - 0.45 * (np.mod(u[k], 0.14) < 0.035))[:, None]
        if kind_of[KIND_WALL] or kind_of[KIND_BARRIER]:
            k = np.flatnonzero((kind == KIND_WALL) | (kind == KIND_BARRIER))
            col[k] *= (1.0 - 0.2 * (np.mod(u[k], 2.5) < 0.03) + 0.06 * tex[k])[:, None]
        if look.night and kind_of[KIND_POLE]:
            glow[(kind == KIND_POLE) & (z > height - 0.35)] = SODIUM * 3.0

    def _building(self, look, k, track, hsh, u, z, side_face, tex, col, glow, spec) -> None:
        """Facades, windows, shop fronts and roofs of the building pixels ``k`` (in place)."""
        spacing = (2.2 + (hsh % 7) * 0.25).astype(np.float32)
        storey = (2.9 + (hsh % 3) * 0.3).astype(np.float32)
        win_w = (0.35 + (hsh % 4) * 0.1).astype(np.float32)
        fu = np.mod(u / spacing, 1.0)
        fz = np.mod(z / storey, 1.0)
        win = side_face & (z > 3.0) & (np.abs(fu - 0.5) < win_w / 2) & (fz > 0.3) & (fz < 0.82)
        shop = side_face & (hsh % 3 == 0) & (z > 0.4) & (z < 2.7) & (fu > 0.08) & (fu < 0.92)
        glass = win | shop
        g = k[glass]
        if len(g):
            col[g] = WINDOW * (1.0 + 0.5 * _sample(self.mid, u[glass] / 0.6, z[glass] / 0.6)[:, None])
            spec[g] = 0.35
            if look.night:
                cell = _hash(track[glass] * 977 + np.floor(u[glass] / spacing[glass]).astype(np.int64) * 31 +
                             np.floor(z[glass] / storey[glass]).astype(np.int64), 5)
                glow[g] = WINDOW_GLOW * (cell < 350)[:, None]
        brick = ~glass & side_face & (hsh % 4 == 1)
        col[k[brick]] *= (0.9 + 0.1 * (np.mod(z[brick], 0.075) > 0.012))[:, None]
        roof = ~side_face
        col[k[roof]] = ROOF[hsh[roof] % len(ROOF)]
        wall = ~glass
        col[k[wall]] *= (1.0 + 0.08 * tex[wall])[:, None]

    def _vehicle(self, boxes, bi, kind, on_x, on_y, nx, ny, u, ulen, z, height, track, k, col, glow, spec,
                 look) -> None:
        """Paint, glass, lamps, plates and bumpers of the vehicle pixels ``k`` (in place; the other
        arguments are already taken at ``k``)."""
        facing = boxes.fronts[bi]
        axis = np.full(len(bi), -1)
        sign = np.zeros(len(bi), np.float32)
        for code, (a, s) in FACING_AXES.items():
            m = facing == code
            axis[m], sign[m] = a, s
        n_along = np.where(axis == 0, nx, np.where(axis == 1, ny, 0.0))
        front = n_along * sign > 0.5
        rear = n_along * sign < -0.5
        sides = on_x | on_y
        flank = sides & ~front & ~rear
        body = kind == KIND_VEHICLE
        cabin = ~body
        spec[k[body]] = 0.45
        zr = z / height
        bus = body & (boxes.cls[bi] == sm.BUS)
        if bus.any():
            win = bus & sides & (zr > 0.45) & (zr < 0.88)
            col[k[win]] = GLASS
            spec[k[win]] = 0.8
        if cabin.any():
            # glass on every side, pillars at the corners, the roof in body colour
            pillar = np.minimum(u, ulen - u) < 0.1
            glass = cabin & sides & ~pillar & (z < 0.9 * height)
            col[k[glass]] = GLASS
            spec[k[glass]] = 0.9
            spec[k[cabin & ~glass]] = 0.45
        ends = body & ~bus & (front | rear)
        if ends.any():
            edge = np.minimum(u, ulen - u)
            lamp = ends & (zr > 0.45) & (zr < 0.85) & (edge < 0.35)
            col[k[lamp & front]] = HEADLAMP
            col[k[lamp & rear]] = TAILLAMP
            plate = ends & (np.abs(u - ulen / 2) < 0.26) & (zr > 0.2) & (zr < 0.42)
            col[k[plate]] = PLATE[(_hash(track[plate], 4) % 4 == 0).astype(np.intp)]
            low = (ends | (flank & body)) & (zr < 0.22)
            bumper = low & (_hash(boxes.track, 6)[bi] % 2 == 0) if low.any() else low
            col[k[bumper]] = BUMPER
            if look.night:
                glow[k[lamp & front]] = LAMP_GLOW
                glow[k[lamp & rear]] = TAIL_GLOW


def _mirror(look, sun, dk, nxk, nyk, nzk, spec, lit) -> np.ndarray:
    """The light a mirror-like face (share ``spec``) adds: the sky by Fresnel, and the sun's glint when it
    shines (``lit``: how much of it reaches the face)."""
    n_ = np.sqrt(dk[0] ** 2 + dk[1] ** 2 + dk[2] ** 2)
    dn = (nxk * dk[0] + nyk * dk[1] + nzk * dk[2]) / n_
    fres = spec * (0.06 + 0.94 * (1.0 - np.abs(dn)) ** 5)
    env = np.asarray(look.sky_horizon, np.float32) * np.float32(0.6 + 0.4 * (look.ambient > 0.3))
    add = (fres + 0.08 * spec)[:, None] * env
    if look.sun_strength > 0.15:
        # sun glint: the mirror direction of the view ray about the face normal
        refl = ((dk[0] / n_ - 2 * dn * nxk) * sun[0] + (dk[1] / n_ - 2 * dn * nyk) * sun[1] +
                (dk[2] / n_ - 2 * dn * nzk) * sun[2])
        glint = np.maximum(refl, np.float32(0.0))
        for _ in range(6):          # ** 64, a tight highlight
            glint *= glint
        glint *= lit
        add += (spec * glint * np.float32(2.0 * look.sun_strength))[:, None] * np.asarray(look.sun_color, np.float32)
    return add
