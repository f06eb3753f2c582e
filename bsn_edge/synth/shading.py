"""Appearance of the synthetic world: textures, lighting, fog, sky and sensor effects.

Shading runs once per frame over compact arrays of ground and object pixels, so its
cost does not grow with the number of boxes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.synth.boxes import (
    KIND_BUILDING,
    KIND_CROWN,
    KIND_PERSON,
    KIND_VEHICLE,
    Boxes,
)

if TYPE_CHECKING:
    from bsn_edge.synth.render import Trace
    from bsn_edge.synth.world import World

TEX = 256            # texture tile size (texels); a power of two so wrapping is a mask
GROUND_TEXEL = 0.08  # metres per texel of the fine ground texture
COARSE_TEXEL = 1.6   # metres per texel of the large-scale stains
NOISE_PAD = 97       # sensor noise: each frame reads a window of a larger tile at its own offset

WINDOW = np.array([0.32, 0.27, 0.22], np.float32)
GLASS = np.array([0.16, 0.14, 0.13], np.float32)
TYRE = np.array([0.07, 0.07, 0.07], np.float32)
ROOF = np.array([0.33, 0.33, 0.35], np.float32)
SKIN = np.array([0.50, 0.62, 0.78], np.float32)
TROUSERS = np.array([0.22, 0.17, 0.15], np.float32)


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
    iu = np.floor(u).astype(np.int64) & (TEX - 1)
    iv = np.floor(v).astype(np.int64) & (TEX - 1)
    return tex[iv, iu]


class Shader:
    """Turns a :class:`Trace` into a BGR image."""

    def __init__(self, height: int, width: int, seed: int = 7) -> None:
        rng = np.random.default_rng(seed)
        self.fine = periodic_noise(rng, TEX, 0.25)
        self.coarse = periodic_noise(rng, TEX, 0.03)
        self.mid = periodic_noise(rng, TEX, 0.08)
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
        r2 = ((xx - width / 2) / (width / 2)) ** 2 + ((yy - height / 2) / (height / 2)) ** 2
        self.vignette = (1.0 - 0.18 * r2 / 2)[..., None].astype(np.float32)
        # Fresh-looking noise every frame without drawing it: a frame's window into this tile
        # starts at an offset of its own. Noise that repeats in image space would give a
        # feature tracker corners that never move.
        self.sensor = rng.standard_normal((height + NOISE_PAD, width + NOISE_PAD, 3)).astype(np.float32)
        self._shape = (height, width)
        self._ray_norm2: np.ndarray | None = None
        self._cache_key: tuple | None = None
        self._cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def set_rays(self, rays: np.ndarray) -> None:
        """Camera-frame rays ``[H, W, 3]``; their squared lengths normalise elevation."""
        self._ray_norm2 = (rays**2).sum(axis=-1).astype(np.float32)

    def shade(self, world: World, boxes: Boxes, tr: Trace, ground_cls: np.ndarray,
              marking: np.ndarray, curb: np.ndarray, obj: np.ndarray, T_wc: np.ndarray,
              frame_index: int) -> np.ndarray:
        look = world.look
        sky, gain, noise = self._per_clip(look, tr.dirs[2], T_wc)
        out = sky.copy()
        flat = out.reshape(-1, 3)
        sun = np.asarray(look.sun, np.float32)
        amb = np.float32(look.ambient)

        gi = np.flatnonzero(tr.ground & ~obj)
        if len(gi):
            flat[gi] = self._ground(look, tr, ground_cls, marking, curb, gi, amb, sun)
        oi = np.flatnonzero(obj)
        if len(oi):
            flat[oi] = self._objects(boxes, tr, T_wc, oi, amb, sun)
        hit = np.flatnonzero(obj | tr.ground)
        if len(hit):
            fog = np.exp(-tr.t.reshape(-1)[hit] / np.float32(look.fog_distance))[:, None]
            haze = np.asarray(look.haze, np.float32)
            flat[hit] = flat[hit] * fog + haze * (1 - fog)
        out *= gain
        h, w = self._shape
        dy, dx = (frame_index * 37) % NOISE_PAD, (frame_index * 61 + 13) % NOISE_PAD
        out += noise[dy:dy + h, dx:dx + w]
        np.clip(out, 0, 255, out=out)
        return out.astype(np.uint8)

    def _per_clip(self, look, dz: np.ndarray, T_wc: np.ndarray):
        """Sky gradient, vignetted gain and scaled sensor noise; constant while the look and the
        camera's pitch are (the sky depends on the rays' world z only, which yaw leaves alone)."""
        key = (look, tuple(T_wc[2, :3].tolist()))
        if self._cache_key != key:
            elev = dz / np.sqrt(self._ray_norm2)
            mix = np.clip(elev * 2.5, 0.0, 1.0)[..., None]
            hor = np.asarray(look.sky_horizon, np.float32)
            sky = hor + mix * (np.asarray(look.sky_zenith, np.float32) - hor)
            gain = self.vignette * (np.asarray(look.tint, np.float32) * np.float32(look.exposure * 255.0))
            self._cache = (sky.astype(np.float32), gain.astype(np.float32),
                           self.sensor * np.float32(look.noise_sigma))
            self._cache_key = key
        return self._cache

    def _ground(self, look, tr, ground_cls, marking, curb, gi, amb, sun) -> np.ndarray:
        cls = ground_cls.reshape(-1)[gi]
        gx, gy = tr.gx.reshape(-1)[gi], tr.gy.reshape(-1)[gi]
        t = tr.t.reshape(-1)[gi]
        lut = np.zeros((256, 3), np.float32)
        lut[sm.ROAD], lut[sm.SIDEWALK], lut[sm.TERRAIN] = look.road, look.sidewalk, look.terrain
        amp = np.zeros(256, np.float32)
        amp[sm.ROAD], amp[sm.SIDEWALK], amp[sm.TERRAIN] = 0.10, 0.06, 0.25
        base = lut[cls]
        base[curb.reshape(-1)[gi]] *= 1.15
        mk = marking.reshape(-1)[gi]
        base[mk] = look.marking
        # paving joints on sidewalks
        side = cls == sm.SIDEWALK
        joints = side & ((np.mod(gx, 0.6) < 0.04) | (np.mod(gy, 0.6) < 0.04))
        base[joints] *= 0.85
        fade = np.clip(1.0 - t / 60.0, 0.15, 1.0)
        fine = _sample(self.fine, gx / GROUND_TEXEL, gy / GROUND_TEXEL) * amp[cls] * fade
        coarse = _sample(self.coarse, gx / COARSE_TEXEL, gy / COARSE_TEXEL) * 0.07
        shade = (amb + (1 - amb) * max(float(sun[2]), 0.0)) * (1.0 + fine + coarse)
        return base * shade[:, None]

    def _objects(self, boxes: Boxes, tr, T_wc, oi, amb, sun) -> np.ndarray:
        C = T_wc[:3, 3].astype(np.float32)
        bi = tr.box.reshape(-1)[oi]
        t = tr.t.reshape(-1)[oi]
        px, py, pz = (C[a] + t * tr.dirs[a].reshape(-1)[oi] for a in range(3))
        # per-box constants first (few boxes), then one gather per pixel
        lo_b = boxes.lo.astype(np.float32)
        hi_b = boxes.hi.astype(np.float32)
        mid_b = 0.5 * (lo_b + hi_b)
        inv_half_b = 2.0 / (hi_b - lo_b)
        rx = (px - mid_b[bi, 0]) * inv_half_b[bi, 0]
        ry = (py - mid_b[bi, 1]) * inv_half_b[bi, 1]
        rz = np.maximum((pz - mid_b[bi, 2]) * inv_half_b[bi, 2], 0.0)  # bottoms are never seen
        ax, ay = np.abs(rx), np.abs(ry)
        on_x = (ax >= ay) & (ax >= rz)
        on_y = ~on_x & (ay >= rz)
        side_face = on_x | on_y
        ndotl = np.where(on_x, sun[0] * np.sign(rx), np.where(on_y, sun[1] * np.sign(ry), sun[2]))
        light = amb + (1 - amb) * np.maximum(ndotl, 0.0)
        lo = lo_b[bi]
        u = np.where(on_x, py - lo[:, 1], px - lo[:, 0])
        z = pz - lo[:, 2]
        height = (hi_b[:, 2] - lo_b[:, 2])[bi]
        kind = boxes.kind[bi]
        track = boxes.track[bi]
        col = boxes.color[bi].copy()
        tex = _sample(self.fine, u / 0.05, z / 0.05)

        b = kind == KIND_BUILDING
        if b.any():
            spacing = 2.6 + (track % 5) * 0.3
            fu = np.mod(u / spacing, 1.0)
            fz = np.mod(z / 3.0, 1.0)
            win = b & side_face & (z > 3.0) & (fu > 0.25) & (fu < 0.75) & (fz > 0.3) & (fz < 0.8)
            shop = b & side_face & (track % 3 == 0) & (z > 0.4) & (z < 2.6) & (fu > 0.08) & (fu < 0.92)
            glass = win | shop
            col[glass] = WINDOW * (1.0 + 0.5 * _sample(self.mid, u[glass] / 0.6, z[glass] / 0.6)[:, None])
            col[b & ~side_face] = ROOF
            col[b & ~glass] *= (1.0 + 0.08 * tex[b & ~glass])[:, None]
        v = kind == KIND_VEHICLE
        if v.any():
            zr = z / height
            col[v & side_face & (zr > 0.58) & (zr < 0.92)] = GLASS
            col[v & side_face & (zr < 0.28)] = TYRE
        pz = kind == KIND_PERSON
        if pz.any():
            zr = z / height
            col[pz & (zr < 0.47)] = TROUSERS
            col[pz & (zr > 0.86)] = SKIN
        cr = kind == KIND_CROWN
        if cr.any():
            clump = _sample(self.mid, u[cr] / 0.15, z[cr] / 0.15)
            col[cr] *= (0.75 + 0.45 * clump)[:, None]
        col *= (1.0 + 0.04 * tex)[:, None]
        return col * light[:, None]
