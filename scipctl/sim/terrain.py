"""Terrain: a height field and the graded grid that triangulates it (pure numerics).

Site frame: +x north, +y east, +z **down**; the terrain is ``z = -h(x, y)``, ``h``
a sum of sinusoids with random directions (wavelengths 0.2 - 60 m, amplitude about
0.4 % of the wavelength: rolling ground, cm-scale bumps). The grid is 2 cm within
4 m of the target rock (at the site origin) and grows geometrically outside (no
cracks: one tensor-product grid), to +-150 m; wavelengths the local grid cannot
carry are faded out there.

Arrays: ``xy`` ``(N, 2)`` site frame metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INNER_HALF_M = 4.0
INNER_STEP_M = 0.02
OUTER_HALF_M = 150.0
GROWTH = 1.07
MAX_STEP_M = 4.0


@dataclass(frozen=True)
class HeightField:
    """``h(x, y) = sum_k a_k sin(k_k . (x, y) + phi_k)`` metres above the datum (site z = -h)."""

    wavevectors: np.ndarray  # (K, 2) rad/m
    amplitudes_m: np.ndarray  # (K,)
    phases_rad: np.ndarray  # (K,)

    @property
    def wavelengths_m(self) -> np.ndarray:
        return 2 * np.pi / np.linalg.norm(self.wavevectors, axis=1)

    def _fade(self, spacing_m):
        if spacing_m is None:
            return 1.0
        # a wave needs >= 8 grid steps per wavelength to be carried; fade between 8 and 16
        r = self.wavelengths_m[None, :] / np.maximum(np.asarray(spacing_m, float)[:, None], 1e-9)
        return np.clip((r - 8.0) / 8.0, 0.0, 1.0)

    def height_and_gradient(self, xy, spacing_m=None, chunk: int = 32768):
        """``xy`` ``(N, 2)`` -> heights ``(N,)`` (positive up) and gradients ``(N, 2)`` (dh/dx, dh/dy).

        ``spacing_m`` ``(N,)``: fade out waves too short for a grid of that spacing (as the mesh is built).
        """
        xy = np.asarray(xy, float)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy: expected shape (N, 2), got {xy.shape}")
        N = len(xy)
        h = np.zeros(N)
        g = np.zeros((N, 2))
        if spacing_m is None:
            groups = [(np.arange(N), np.arange(len(self.amplitudes_m)))]
        else:
            sp = np.broadcast_to(np.asarray(spacing_m, float), (N,))
            # waves a vertex can carry at all (fade > 0): wavelength > 8 x spacing; group vertices by that set
            need = np.searchsorted(np.sort(-self.wavelengths_m), -8.0 * sp, side="left")  # count of long-enough waves
            order = np.argsort(-self.wavelengths_m, kind="stable")
            groups = [(np.nonzero(need == k)[0], order[:k]) for k in np.unique(need) if k > 0]
        for vid, wid in groups:
            K = self.wavevectors[wid]
            for i in range(0, len(vid), chunk):
                sel = vid[i:i + chunk]
                ph = xy[sel] @ K.T
                ph += self.phases_rad[wid][None, :]
                w = self.amplitudes_m[wid][None, :]
                if spacing_m is not None:
                    r = self.wavelengths_m[wid][None, :] / np.maximum(sp[sel][:, None], 1e-9)
                    w = w * np.clip((r - 8.0) / 8.0, 0.0, 1.0)
                h[sel] = np.einsum("ij,ij->i", np.sin(ph), w)
                g[sel] = (np.cos(ph) * w) @ K
        return h, g

    def height_m(self, xy, spacing_m=None) -> np.ndarray:
        """``xy`` ``(N, 2)`` -> ``(N,)`` heights (positive up)."""
        return self.height_and_gradient(xy, spacing_m)[0]

    def gradient(self, xy, spacing_m=None) -> np.ndarray:
        """``(N, 2)`` = (dh/dx, dh/dy)."""
        return self.height_and_gradient(xy, spacing_m)[1]

    def normal_site(self, xy, spacing_m=None) -> np.ndarray:
        """Upward unit normal ``(N, 3)`` in the site frame (z down): ``(-hx, -hy, -1)/norm``."""
        g = self.gradient(xy, spacing_m)
        n = np.concatenate([-g, -np.ones((g.shape[0], 1))], axis=1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def random_height_field(rng: np.random.Generator, n_waves: int = 48, roughness: float = 0.004,
                        wavelength_range_m: tuple = (0.2, 60.0)) -> HeightField:
    """``n_waves`` sinusoids, wavelengths log-uniform in ``wavelength_range_m``, amplitude ``roughness`` x
    wavelength x U(0.4, 1), random directions and phases."""
    lam = np.exp(rng.uniform(np.log(wavelength_range_m[0]), np.log(wavelength_range_m[1]), size=n_waves))
    lam.sort()
    ang = rng.uniform(0, 2 * np.pi, size=n_waves)
    k = (2 * np.pi / lam)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    amp = roughness * lam * rng.uniform(0.4, 1.0, size=n_waves)
    phase = rng.uniform(0, 2 * np.pi, size=n_waves)
    return HeightField(k, amp, phase)


def graded_axis(inner_half_m=INNER_HALF_M, inner_step_m=INNER_STEP_M, outer_half_m=OUTER_HALF_M,
                growth=GROWTH, max_step_m=MAX_STEP_M) -> np.ndarray:
    """Grid line positions ``(K,)``: uniform in ``[-inner, inner]``, geometric growth outside, to ``+-outer``."""
    n_in = int(round(inner_half_m / inner_step_m))
    inner = np.arange(-n_in, n_in + 1) * inner_step_m
    outer = []
    x, step = inner_half_m, inner_step_m
    while x < outer_half_m:
        step = min(step * growth, max_step_m)
        x = min(x + step, outer_half_m)
        outer.append(x)
    outer = np.array(outer)
    return np.concatenate([-outer[::-1], inner, outer])


def grid_mesh(xs: np.ndarray, ys: np.ndarray):
    """Tensor grid -> (vertex xy ``(nx*ny, 2)``, triangles ``(2(nx-1)(ny-1), 3)``, local spacing ``(nx*ny,)``)."""
    nx, ny = len(xs), len(ys)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    xy = np.stack([X.ravel(), Y.ravel()], axis=1)
    dx = np.maximum(np.diff(xs, prepend=xs[0] - (xs[1] - xs[0])), np.diff(xs, append=xs[-1] + (xs[-1] - xs[-2])))
    dy = np.maximum(np.diff(ys, prepend=ys[0] - (ys[1] - ys[0])), np.diff(ys, append=ys[-1] + (ys[-1] - ys[-2])))
    spacing = np.maximum(dx[:, None], dy[None, :]).ravel()
    idx = np.arange(nx * ny).reshape(nx, ny)
    a = idx[:-1, :-1].ravel()
    b = idx[1:, :-1].ravel()
    c = idx[1:, 1:].ravel()
    d = idx[:-1, 1:].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return xy, tris, spacing


# ----------------------------------------------------------------------------- bedrock slabs
def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass(frozen=True)
class SlabField:
    """Bedrock slabs: flat plates (Voronoi cells of jittered seeds on a ``cell_m`` grid, each a tilted plane) on a
    low rolling ``base``, meeting in small steps (blended over ``step_blend_m``) and dust-filled cracks (up to
    ``crack_depth_m`` deep, ``crack_half_width_m`` each side of the border, each crack as strong as the product of
    its two plates' ``crack_strength``). The cells are looked up at ``xy + warp(xy)`` (a few sinusoids), so the
    cracks wander. Same interface as :class:`HeightField` (heights positive up, site +z down); gradients: the
    base's analytic, a plate's plane inside it, central differences (1 mm) within a blend width of a border. The
    height is continuous except near plate corners (three plates), where the step and crack switch to the nearer
    border: measured over 400 000 random 0.5 mm steps within 4 m, 0.003 % changed the height by > 1 mm (max 11 mm)."""

    base: HeightField
    cell_m: float
    jitter: np.ndarray  # (n, n, 2) seed offsets in cells, [-0.4, 0.4]
    plate_height_m: np.ndarray  # (n, n)
    plate_slope: np.ndarray  # (n, n, 2) dh/dx, dh/dy of each plate
    crack_strength: np.ndarray  # (n, n) in (0, 1]
    warp: HeightField  # its sinusoids displace x (even-numbered waves) and y (odd-numbered)
    step_blend_m: float = 0.05
    crack_half_width_m: float = 0.03
    crack_depth_m: float = 0.02
    half_extent_m: float = OUTER_HALF_M + 8.0

    def _seed(self, c):
        return (c + 0.5 + self.jitter[c[:, 0], c[:, 1]]) * self.cell_m - self.half_extent_m

    def _cells(self, xy):
        """The plate of ``xy`` ``(N, 2)`` and its nearest border: ``(cell1 (N, 2) int, seed1_xy (N, 2), cell2,
        seed2_xy, border_m (N,), crack strength (N,))`` -- cell 1 holds the nearest seed, ``border_m`` is the
        distance to the nearest Voronoi edge (the bisector with seed 2, over the 3 x 3 neighbouring cells; continuous),
        all in the warped plane."""
        n = self.plate_height_m.shape[0]
        ph = xy @ self.warp.wavevectors.T + self.warp.phases_rad
        w = np.sin(ph) * self.warp.amplitudes_m
        xy = xy + np.stack([w[:, 0::2].sum(axis=1), w[:, 1::2].sum(axis=1)], axis=1)
        ci = np.floor((xy + self.half_extent_m) / self.cell_m).astype(np.int64)
        cands = [np.clip(ci + np.array([di, dj]), 0, n - 1) for di in (-1, 0, 1) for dj in (-1, 0, 1)]
        best = np.full(len(xy), np.inf)
        c1 = np.zeros((len(xy), 2), np.int64)
        for c in cands:
            d2 = np.sum((xy - self._seed(c)) ** 2, axis=1)
            first = d2 < best
            best = np.where(first, d2, best)
            c1 = np.where(first[:, None], c, c1)
        s1 = self._seed(c1)
        border = np.full(len(xy), np.inf)
        c2 = c1.copy()
        for c in cands:
            sc = self._seed(c)
            gap = np.linalg.norm(sc - s1, axis=1)
            other = np.any(c != c1, axis=1)
            bj = np.where(other, (np.sum((xy - sc) ** 2, axis=1) - best) / (2.0 * np.maximum(gap, 1e-9)), np.inf)
            closer = bj < border
            border = np.where(closer, bj, border)
            c2 = np.where(closer[:, None], c, c2)
        s2 = self._seed(c2)
        strength = self.crack_strength[c1[:, 0], c1[:, 1]] * self.crack_strength[c2[:, 0], c2[:, 1]]
        return c1, s1, c2, s2, border, strength

    def _plate(self, idx, s, xy):
        return self.plate_height_m[idx[:, 0], idx[:, 1]] + np.sum(self.plate_slope[idx[:, 0], idx[:, 1]] * (xy - s), axis=1)

    def _slab_height(self, xy, spacing_m, detail: bool = False):
        """Slab part of the height ``(N,)``; ``detail``: also ``(border_m, nearest cell (N, 2), reach_m)``, where
        farther than ``reach_m`` from the border the height is the nearest plate's plane."""
        i1, s1, i2, s2, b, strength = self._cells(xy)
        p1, p2 = self._plate(i1, s1, xy), self._plate(i2, s2, xy)
        sp = np.zeros(len(xy)) if spacing_m is None else np.broadcast_to(np.asarray(spacing_m, float), (len(xy),))
        blend = np.maximum(self.step_blend_m, 1.5 * sp)
        h = p1 + (p2 - p1) * 0.5 * (1.0 - _smoothstep(b / blend))
        w = np.maximum(self.crack_half_width_m, 1.5 * sp)  # a grid too coarse for the crack gets a wide shallow one
        h -= strength * self.crack_depth_m * (self.crack_half_width_m / w) * (1.0 - _smoothstep(b / w))
        return (h, b, i1, np.maximum(blend, w)) if detail else h

    def exposure(self, xy, spacing_m=None) -> np.ndarray:
        """``(N,)`` float32: 1 on bare plate, down to 0 in the dust of a strong crack (for the appearance). With
        ``spacing_m`` ``(N,)`` a grid too coarse for the crack gets a wide faint one, as the height does."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        _, _, _, _, b, strength = self._cells(xy)
        sp = np.zeros(len(xy)) if spacing_m is None else np.broadcast_to(np.asarray(spacing_m, float), (len(xy),))
        w = np.maximum(self.crack_half_width_m, 1.5 * sp)
        dust = (self.crack_half_width_m / w) * (1.0 - _smoothstep((b - w) / w))
        return (1.0 - strength * dust).astype(np.float32)

    def height_and_gradient(self, xy, spacing_m=None):
        """``xy`` ``(N, 2)`` -> heights ``(N,)`` (positive up) and gradients ``(N, 2)``."""
        xy = np.asarray(xy, float)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy: expected shape (N, 2), got {xy.shape}")
        e = 1e-3
        h, g = self.base.height_and_gradient(xy, spacing_m)
        hs, b, i1, reach = self._slab_height(xy, spacing_m, detail=True)
        h = h + hs
        # inside a plate (beyond the blends, with 2 mm to spare for the 1 mm steps stretched by the warp) the slab
        # is its plate's plane; near a border, central differences
        g = g + self.plate_slope[i1[:, 0], i1[:, 1]]
        near = np.flatnonzero(b <= reach + 2e-3)
        if len(near):
            q = xy[near]
            sp = None if spacing_m is None else np.broadcast_to(np.asarray(spacing_m, float), (len(xy),))[near]
            fd = np.stack([self._slab_height(q + [e, 0.0], sp) - self._slab_height(q - [e, 0.0], sp),
                           self._slab_height(q + [0.0, e], sp) - self._slab_height(q - [0.0, e], sp)], axis=1) / (2 * e)
            g[near] += fd - self.plate_slope[i1[near, 0], i1[near, 1]]
        return h, g

    def height_m(self, xy, spacing_m=None) -> np.ndarray:
        xy = np.asarray(xy, float).reshape(-1, 2)
        return self.base.height_m(xy, spacing_m) + self._slab_height(xy, spacing_m)

    def gradient(self, xy, spacing_m=None) -> np.ndarray:
        return self.height_and_gradient(xy, spacing_m)[1]

    def normal_site(self, xy, spacing_m=None) -> np.ndarray:
        g = self.gradient(xy, spacing_m)
        n = np.concatenate([-g, -np.ones((g.shape[0], 1))], axis=1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)


@dataclass(frozen=True)
class GridValues:
    """Values ``(n * n,)`` at the vertices of the tensor grid ``axis_m`` x ``axis_m`` (vertex ``i * n + j`` at
    ``(axis[i], axis[j])``, as :func:`grid_mesh`), interpolated on the grid's triangles (a, b, c) / (a, c, d) as the
    terrain mesh is: ``values(xy)`` -> ``(N,)`` float32 (points outside the grid take the border's values). Used for
    the bedrock's exposure: computed once per vertex, so the albedo costs a lookup per sample."""

    axis_m: np.ndarray  # (n,)
    values: np.ndarray  # (n * n,)

    def __call__(self, xy) -> np.ndarray:
        xy = np.asarray(xy, float).reshape(-1, 2)
        ax = self.axis_m
        n = len(ax)
        x = np.clip(xy[:, 0], ax[0], ax[-1])
        y = np.clip(xy[:, 1], ax[0], ax[-1])
        i = np.clip(np.searchsorted(ax, x, side="right") - 1, 0, n - 2)
        j = np.clip(np.searchsorted(ax, y, side="right") - 1, 0, n - 2)
        fx = (x - ax[i]) / (ax[i + 1] - ax[i])
        fy = (y - ax[j]) / (ax[j + 1] - ax[j])
        v = self.values
        va, vb, vc, vd = v[i * n + j], v[(i + 1) * n + j], v[(i + 1) * n + j + 1], v[i * n + j + 1]
        out = np.where(fx >= fy, va + fx * (vb - va) + fy * (vc - vb), va + fy * (vd - va) + fx * (vc - vd))
        return out.astype(np.float32)


# ----------------------------------------------------------------------------- terrain kinds
@dataclass(frozen=True)
class GroundParams:
    """What a terrain kind sets besides its height field: rocks, pebbles and drift sand around the target rock.

    ``near_rocks``: rocks tried ``near_rock_min_m``-4 m from the target rock (sizes ``near_rock_size_m``), ``far_rock_tries``: rocks
    tried 4-25 m out (``far_rock_size_m``); ``pebble_counts``: pebbles tried in the three zones (fine near, coarse
    near, outer 4-16 m), ``pebble_size_scale`` multiplies their sizes; ``sand_patches``: drift-sand patches near the
    rock (radius ``sand_radius_m``); ``sand_sheet_m``: radius of a sand sheet covering the ground around the rock
    (0: none; pebbles may lie on it); ``bedrock``: the height field is a :class:`SlabField` whose plates look like
    rock; ``corridor_rock_max_m``: rocks up to this length may lie in the rover's approach corridors (cobbles a
    rover drives over; its wheels do not feel them, as with pebbles)."""

    near_rocks: int = 5
    near_rock_size_m: tuple = (0.2, 0.45)
    near_rock_min_m: float = 1.0
    far_rock_tries: int = 40
    far_rock_size_m: tuple = (0.2, 0.6)
    pebble_counts: tuple = (1100, 160, 900)
    pebble_size_scale: float = 1.0
    sand_patches: int = 3
    sand_radius_m: tuple = (0.3, 0.55)
    sand_sheet_m: float = 0.0
    bedrock: bool = False
    corridor_rock_max_m: float = 0.0

    def check(self) -> "GroundParams":
        if self.near_rocks < 0 or self.far_rock_tries < 0 or self.sand_patches < 0 or min(self.pebble_counts) < 0:
            raise ValueError("GroundParams: counts must be >= 0")
        if len(self.pebble_counts) != 3:
            raise ValueError("GroundParams.pebble_counts: three zones")
        for lo, hi in (self.near_rock_size_m, self.far_rock_size_m, self.sand_radius_m):
            if not 0 < lo <= hi:
                raise ValueError("GroundParams: size ranges must be 0 < lo <= hi")
        if not 0 < self.pebble_size_scale <= 3 or self.sand_sheet_m < 0:
            raise ValueError("GroundParams: pebble_size_scale in (0, 3], sand_sheet_m >= 0")
        return self


@dataclass(frozen=True)
class Ground:
    """A terrain kind's draw: the height field (:class:`HeightField` or :class:`SlabField`) and its :class:`GroundParams`."""

    field: object
    params: GroundParams


def rolling_ground(rng: np.random.Generator) -> Ground:
    """Today's ground (the ``default`` family): rolling soil with cm bumps, a few rocks, pebbles, 1-3 sand patches."""
    return Ground(random_height_field(rng), GroundParams())


def bedrock_slabs(rng: np.random.Generator) -> Ground:
    """Flat bedrock plates ~1.6 m across, 1-2 cm steps and wandering dusty cracks of varied strength between them,
    on a gentle roll; few pebbles, one small sand patch."""
    base = random_height_field(rng, roughness=0.0015, wavelength_range_m=(2.0, 60.0))
    cell = 1.6
    n = int(np.ceil(2 * (OUTER_HALF_M + 8.0) / cell)) + 1
    jitter = rng.uniform(-0.4, 0.4, size=(n, n, 2))
    heights = rng.normal(0.0, 0.012, size=(n, n))
    slopes = rng.normal(0.0, 0.015, size=(n, n, 2))
    strength = rng.uniform(0.15, 1.0, size=(n, n))
    warp = random_height_field(rng, n_waves=8, roughness=0.04, wavelength_range_m=(1.0, 4.0))
    field = SlabField(base, cell, jitter, heights, slopes, strength, warp)
    return Ground(field, GroundParams(near_rocks=3, pebble_counts=(250, 40, 300), sand_patches=1, bedrock=True))


def sand_sheet(rng: np.random.Generator) -> Ground:
    """A smooth sand sheet (no relief shorter than 0.8 m) over the whole scene, wind ripples, sparse pebbles lying
    on it and few rocks: low texture everywhere."""
    field = random_height_field(rng, roughness=0.0025, wavelength_range_m=(0.8, 60.0))
    return Ground(field, GroundParams(near_rocks=2, far_rock_tries=15, pebble_counts=(120, 20, 200), sand_patches=0,
                                      sand_sheet_m=200.0))


def pebble_field(rng: np.random.Generator) -> Ground:
    """Rolling ground paved with pebbles: three times today's count, up to 1.5 times larger; no sand."""
    return Ground(random_height_field(rng), GroundParams(pebble_counts=(3300, 480, 2700), pebble_size_scale=1.5,
                                                         sand_patches=0))


def rock_strewn(rng: np.random.Generator) -> Ground:
    """Rolling ground strewn with rocks: 30 tried within 0.6-4 m of the target rock, 150 further out; cobbles up to
    18 cm long may lie in the approach corridors, larger rocks stay outside."""
    return Ground(random_height_field(rng), GroundParams(near_rocks=30, near_rock_size_m=(0.08, 0.45), near_rock_min_m=0.6,
                                                         far_rock_tries=150,
                                                         far_rock_size_m=(0.1, 0.7), corridor_rock_max_m=0.18))


# name -> generator(rng) -> Ground; one signature, siblings
TERRAIN_KINDS = {
    "rolling": rolling_ground,
    "bedrock-slabs": bedrock_slabs,
    "sand-sheet": sand_sheet,
    "pebble-field": pebble_field,
    "rock-strewn": rock_strewn,
}
