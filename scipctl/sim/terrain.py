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


def random_height_field(rng: np.random.Generator, n_waves: int = 48, roughness: float = 0.004) -> HeightField:
    lam = np.exp(rng.uniform(np.log(0.2), np.log(60.0), size=n_waves))
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
