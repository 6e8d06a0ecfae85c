"""Appearance: procedural Lambertian albedo of the scene's surfaces (pure numerics).

The albedo is a function of the 3-D surface point (multi-octave 3-D value noise with
per-material statistics and high-contrast spots), so it is the same from every
viewpoint. Drift-sand patches (with wind ripples) replace the soil near the target
rock. ``MAT_*`` are the material ids the albedo dispatches on (the scene's ray casts
report them). Points ``(N, 3)`` site frame metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .noise import FractalNoise, LatticeNoise, lod_weight

MAT_SKY, MAT_TERRAIN, MAT_ROCK, MAT_PEBBLE = -1, 0, 1, 2
SPECK_MODES = ("lod", "filtered")


@dataclass(frozen=True)
class SpeckThresholds:
    """Specks of a noise value ``s`` (~[-0.5, 0.5]): one kind where ``s > high_at``, the other where ``-s > low_at``,
    each ramping in over ``ramp``; ``high_is_dark`` says which kind is dark (soil: yes; rock: the high ones are
    bright)."""

    high_at: float
    low_at: float
    ramp: float
    high_is_dark: bool

    def apply(self, s: np.ndarray) -> tuple:
        """``(dark, bright)`` float32 in [0, 1] from ``s`` ``(N,)`` float32."""
        f32 = np.float32
        hi = np.clip((s - f32(self.high_at)) / f32(self.ramp), 0, 1)
        lo = np.clip((-s - f32(self.low_at)) / f32(self.ramp), 0, 1)
        return (hi, lo) if self.high_is_dark else (lo, hi)


SOIL_SPECKS = SpeckThresholds(high_at=0.3, low_at=0.32, ramp=0.06, high_is_dark=True)
ROCK_SPECKS = SpeckThresholds(high_at=0.19, low_at=0.21, ramp=0.05, high_is_dark=False)


@dataclass
class Appearance:
    """Procedural albedo: per-material fractal noise + spots. Call :meth:`albedo`."""

    soil: FractalNoise
    sand: FractalNoise
    rock: FractalNoise
    spots: FractalNoise  # high-contrast specks (thresholded)
    rock_spots: FractalNoise
    patches: FractalNoise  # metre-scale albedo variation of the ground
    sand_patches: np.ndarray  # (K, 3) x, y, radius_m of drift-sand patches
    soil_albedo: float = 0.34
    sand_albedo: float = 0.44
    rock_albedo: float = 0.26
    texture: Optional[object] = None  # a sim.texture.SurfaceTexture: real relative albedo replacing the soil's grain
    bedrock_exposure: Optional[object] = None  # xy (N, 2) -> (N,) in [0, 1]: where 1, the ground is bedrock (sim.terrain.GridValues)
    bedrock_albedo: float = 0.30
    bedrock_cover: float = 0.6  # the plates' rock shows through a dust film: this much rock, the rest soil
    # how the thresholded specks (soil `spots`, rock `rock_spots`) meet a pixel footprint larger than them:
    # "lod" (today's): thresholded from the LOD-faded noise, so they vanish once the footprint passes ~7 mm (a
    # texture that changes with range: docs/simulator.md, "Specks and range"); "filtered": thresholded from the
    # full-detail noise and faded towards their mean cover as the footprint grows (same mean albedo at any range)
    specks: str = "lod"

    def sand_weight(self, xy: np.ndarray) -> np.ndarray:
        """0 (soil) .. 1 (drift sand) ``(N,)``: irregular patches (radius modulated by the angle) with a soft 4 cm edge."""
        w = np.zeros(len(xy), np.float32)
        for x, y, r in self.sand_patches:
            near = np.flatnonzero((np.abs(xy[:, 0] - x) < 1.4 * r) & (np.abs(xy[:, 1] - y) < 1.4 * r))
            if len(near) == 0:
                continue
            dx, dy = xy[near, 0] - x, xy[near, 1] - y
            d = np.hypot(dx, dy)
            a = np.arctan2(dy, dx)
            k = 1000.0 * r  # fixed per patch: a deterministic wobble
            rr = r * (1 + 0.12 * np.sin(3 * a + k) + 0.07 * np.sin(5 * a + 2 * k) + 0.04 * np.sin(11 * a + 3 * k))
            w[near] = np.maximum(w[near], np.clip((rr - d) / 0.04, 0, 1).astype(np.float32))
        return w

    def albedo(self, P: np.ndarray, material: np.ndarray, obj_scale: np.ndarray, footprint_m: Optional[np.ndarray]) -> np.ndarray:
        """Albedo ``(N,)`` float32 of surface points ``P`` ``(N, 3)`` site; ``material`` ``(N,)``; ``obj_scale`` ``(N,)``.

        ``footprint_m`` ``(N,)`` (pixel footprint on the surface) fades octaves finer than a pixel; None = full detail.
        """
        N = P.shape[0]
        out = np.zeros(N, np.float32)
        f32 = np.float32

        def sub(a, idx):
            return None if a is None else a[idx]

        ter = np.flatnonzero(material == MAT_TERRAIN)
        if len(ter):
            PT = np.ascontiguousarray(P[ter].T, np.float32)
            f = sub(footprint_m, ter)
            ws = self.sand_weight(P[ter, :2])
            base = (1 - ws) * f32(self.soil_albedo) + ws * f32(self.sand_albedo)
            patch = self.patches.eval_T(PT, f)
            base *= f32(1.0) + patch
            soil = np.flatnonzero(ws < 1)
            tex = np.zeros(len(ter), np.float32)
            if self.texture is not None:  # real texture: a function of the ground point (x, y), faded by the footprint
                if len(soil):
                    tex[soil] = self.texture.sample(PT[:2, soil].T, sub(f, soil))
            elif len(soil) == len(ter):
                tex = self.soil.eval_T(PT, f)
            elif len(soil):
                tex[soil] = self.soil.eval_T(np.ascontiguousarray(PT[:, soil]), sub(f, soil))
            sel = np.flatnonzero(ws > 0)
            if len(sel):
                sand = self.sand.eval_T(np.ascontiguousarray(PT[:, sel]), sub(f, sel))
                # wind ripples: ~9 cm crests across the prevailing wind, a little wavy (faded below the footprint)
                x, y = PT[0, sel], PT[1, sel]
                ph = f32(2 * np.pi / 0.09) * (f32(0.8) * x + f32(0.6) * y) + f32(1.5) * np.sin(f32(2 * np.pi / 0.7) * (f32(-0.6) * x + f32(0.8) * y))
                rip = f32(0.07) * np.sin(ph)
                if f is not None:
                    rip *= lod_weight(0.09 / 4, f[sel])
                tex[sel] = (1 - ws[sel]) * tex[sel] + ws[sel] * (sand + rip)
            a = base * (f32(1.0) + tex)
            if self.texture is None:  # the real texture carries its own specks
                dark, bright = self._specks(self.spots, SOIL_SPECKS, PT, f)
                dark = dark * (1 - ws)
                bright = bright * (1 - ws)
                a = a * (1 - f32(0.65) * dark) + f32(0.35) * bright
            if self.bedrock_exposure is not None:  # bare plates: rock-like albedo; dust in cracks and under sand stays soil
                w = f32(self.bedrock_cover) * self.bedrock_exposure(P[ter, :2]) * (1 - ws)
                bare = np.flatnonzero(w > 0)
                if len(bare):
                    a[bare] = (1 - w[bare]) * a[bare] + w[bare] * self._rock_like(
                        np.ascontiguousarray(PT[:, bare]), sub(f, bare), f32(self.bedrock_albedo) * (f32(1.0) + patch[bare]))
            out[ter] = a
        rk = np.flatnonzero((material == MAT_ROCK) | (material == MAT_PEBBLE))
        if len(rk):
            PT = np.ascontiguousarray(P[rk].T, np.float32)
            out[rk] = self._rock_like(PT, sub(footprint_m, rk), f32(self.rock_albedo) * obj_scale[rk].astype(np.float32))
        return np.clip(out, 0.02, 0.98).astype(np.float32)

    def _rock_like(self, PT: np.ndarray, footprint_m: Optional[np.ndarray], level: np.ndarray) -> np.ndarray:
        """Rock albedo ``(N,)`` float32 at points ``PT`` ``(3, N)`` float32: ``level`` ``(N,)`` x mottling, with bright
        and dark spots."""
        f32 = np.float32
        a = level * (f32(1.0) + self.rock.eval_T(PT, footprint_m))
        dark, bright = self._specks(self.rock_spots, ROCK_SPECKS, PT, footprint_m)
        return a * (1 - f32(0.6) * dark) + f32(0.4) * bright

    def _specks(self, noise: FractalNoise, th: "SpeckThresholds", PT: np.ndarray, footprint_m: Optional[np.ndarray]):
        """``(dark, bright)`` ``(N,)`` float32 in [0, 1]: the specks of ``noise`` at points ``PT`` ``(3, N)`` (see ``specks``)."""
        if self.specks == "lod" or footprint_m is None:
            return th.apply(noise.eval_T(PT, footprint_m))
        if self.specks not in SPECK_MODES:
            raise ValueError(f"Appearance.specks: {self.specks!r} (want one of {', '.join(SPECK_MODES)})")
        dark, bright = th.apply(noise.eval_T(PT, None))
        mean_dark, mean_bright = self._speck_cover(noise, th)
        # the finest octave's cell is the specks' size: lod_weight's fade (1 up to a footprint of 2/3 cell, 0 from
        # 2 cells on), applied after the threshold rather than to the noise before it
        w = lod_weight(noise.octaves[0].cell_m, footprint_m)
        return w * dark + (1 - w) * np.float32(mean_dark), w * bright + (1 - w) * np.float32(mean_bright)

    def _speck_cover(self, noise: FractalNoise, th: "SpeckThresholds") -> tuple:
        """Mean ``(dark, bright)`` of ``noise``'s specks at full detail, over 2^16 points of a seeded 1 m cube (cached)."""
        key = noise  # by identity (FractalNoise has no __eq__), held by the cache: no id() reuse
        cache = self.__dict__.setdefault("_cover", {})
        if key not in cache:
            P = np.random.default_rng(0x5BEC).uniform(0.0, 1.0, (3, 1 << 16)).astype(np.float32)
            d, b = th.apply(noise.eval_T(P, None))
            cache[key] = (float(d.mean()), float(b.mean()))
        return cache[key]


def make_appearance(rng: np.random.Generator, sand_patches: np.ndarray) -> Appearance:
    lattice = LatticeNoise(rng, 128)
    soil = FractalNoise(lattice, rng, [0.0025, 0.005, 0.01, 0.02, 0.04, 0.09], [0.3, 0.32, 0.3, 0.25, 0.22, 0.18])
    sand = FractalNoise(lattice, rng, [0.002, 0.004, 0.008, 0.02, 0.06], [0.22, 0.18, 0.14, 0.12, 0.12])
    rock = FractalNoise(lattice, rng, [0.003, 0.006, 0.012, 0.025, 0.05, 0.1], [0.35, 0.4, 0.45, 0.5, 0.45, 0.3])
    spots = FractalNoise(lattice, rng, [0.006, 0.012], [1.0, 0.5])
    rock_spots = FractalNoise(lattice, rng, [0.005, 0.01, 0.02], [0.7, 0.6, 0.4])
    patches = FractalNoise(lattice, rng, [0.3, 1.2, 5.0], [0.25, 0.3, 0.3])
    return Appearance(soil, sand, rock, spots, rock_spots, patches, sand_patches)
