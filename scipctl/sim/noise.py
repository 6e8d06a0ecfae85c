"""Seeded 3-D lattice value noise (pure numerics).

A noise field is a periodic random lattice of ``n^3`` values in ``[0, 1]``.
It is evaluated at lattice coordinates ``q`` (``(N, 3)``, unit = one lattice
cell): bilinear in ``(x, y)`` and quintic-faded linear in ``z``. The lattice is
stored as a 2-D "atlas" (the ``z`` slices side by side, each with one wrap-around
row and column); each point's four neighbours are gathered from it and blended
in float32 at the exact position.

(Until issue #12 the blend was ``cv2.remap``: OpenCV 4.x rounds its positions to
1/32 of a cell, and the rounding depended on where a point sat in the batch, so
the albedo of one surface point differed between views and between OpenCV
builds by up to ~1e-3. The gather is ~4x slower per point than remap.)

The value is a deterministic function of ``q`` and the seed: identical from
every viewpoint.
"""

from __future__ import annotations

import numpy as np

class LatticeNoise:
    """Periodic value noise on an ``n^3`` lattice drawn from ``rng`` (a ``numpy.random.Generator``)."""

    def __init__(self, rng: np.random.Generator, n: int = 128):
        if n < 4 or n * (n + 1) >= 32767:
            raise ValueError(f"n: lattice size {n} out of range (4 .. 180)")
        self.n = int(n)
        lat = rng.random((n, n, n), dtype=np.float64).astype(np.float32)  # [z, y, x]
        # atlas: rows = y (n + 1 with wrap), columns = slice z * (n + 1) + x (n + 1 with wrap)
        atlas = np.empty((n + 1, n * (n + 1)), np.float32)
        for k in range(n):
            s = lat[k]
            blk = atlas[:, k * (n + 1):(k + 1) * (n + 1)]
            blk[:n, :n] = s
            blk[:n, n] = s[:, 0]
            blk[n, :n] = s[0, :]
            blk[n, n] = s[0, 0]
        self._atlas = atlas

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """Noise at lattice coordinates ``q`` ``(N, 3)`` -> ``(N,)`` float32 in ``[0, 1]``."""
        q = np.asarray(q)
        if q.ndim != 2 or q.shape[1] != 3:
            raise ValueError(f"q: expected shape (N, 3), got {q.shape}")
        return self.eval_T(np.ascontiguousarray(q.T, np.float32))

    def eval_T(self, qT: np.ndarray) -> np.ndarray:
        """As :meth:`__call__` for transposed coordinates ``qT`` ``(3, N)`` float32 (the fast layout)."""
        N = qT.shape[1]
        if N == 0:
            return np.zeros(0, np.float32)
        n = self.n
        f32 = np.float32
        inv_n = f32(1.0 / n)
        W = n * (n + 1)  # atlas row length
        flat = self._atlas.reshape(-1)

        def cell(c):
            """Wrapped lattice coordinate -> (integer cell in [0, n - 1], fraction in [0, 1]) (float32 arithmetic)."""
            w = c - f32(n) * np.floor(c * inv_n)  # in [0, n]; n itself only by float32 rounding
            i = np.minimum(np.floor(w), f32(n - 1))
            return i.astype(np.int32), w - i

        z = qT[2]
        zf = np.floor(z)
        fz = z - zf
        k0 = (zf - f32(n) * np.floor(zf * inv_n)).astype(np.int32)  # zf mod n (exact for integers)
        k1 = k0 + 1
        k1[k1 >= n] = 0
        xi, fx = cell(qT[0])
        yi, fy = cell(qT[1])
        row = yi * W + xi

        def bilinear(k):
            i00 = row + k * (n + 1)
            v00, v01 = flat[i00], flat[i00 + 1]
            v10, v11 = flat[i00 + W], flat[i00 + W + 1]
            top = v00 + fx * (v01 - v00)
            return top + fy * ((v10 + fx * (v11 - v10)) - top)

        a = bilinear(k0)
        b = bilinear(k1)
        w = fz * fz * fz * (fz * (fz * f32(6) - f32(15)) + f32(10))
        b -= a
        b *= w
        b += a
        return b


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix ``(3, 3)`` (QR of a Gaussian matrix, sign-fixed)."""
    M = rng.normal(size=(3, 3))
    Q, R = np.linalg.qr(M)
    Q = Q @ np.diag(np.sign(np.diag(R)))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


class Octave:
    """One octave: ``noise(R @ p / cell_m + offset)`` for points ``p`` in metres."""

    def __init__(self, rng: np.random.Generator, cell_m: float):
        self.cell_m = float(cell_m)
        self.R = random_rotation(rng)
        self.offset = rng.uniform(0, 1000.0, size=3)
        self._M = np.ascontiguousarray(self.R / self.cell_m, np.float32)
        self._off = self.offset.astype(np.float32)[:, None]

    def coords_T(self, pT_m: np.ndarray) -> np.ndarray:
        """Lattice coordinates ``(3, N)`` float32 of points ``pT_m`` ``(3, N)`` float32 (transposed layout).

        Float32 arithmetic: the rounding is ~1e-7 relative, far below a cell for the fine octaves
        (which are only used near the cameras, see :func:`lod_weight`)."""
        # explicit multiply-adds: a BLAS call for a 3x3 product is slower and oversubscribes threads
        M = self._M
        x, y, z = pT_m[0], pT_m[1], pT_m[2]
        q = np.empty_like(pT_m)
        for k in range(3):
            o = q[k]
            np.multiply(x, M[k, 0], out=o)
            o += y * M[k, 1]
            o += z * M[k, 2]
            o += self._off[k, 0]
        return q


class FractalNoise:
    """A sum of octaves of one :class:`LatticeNoise` with per-octave random rotations and offsets.

    ``cells_m`` lists the octave cell sizes; ``weights`` their amplitudes.
    Evaluation returns ``sum_k w_k * lod_k * (noise_k - 0.5)``; ``lod_k`` fades
    out octaves finer than the pixel footprint (anti-aliasing, see
    :func:`lod_weight`).
    """

    def __init__(self, lattice: LatticeNoise, rng: np.random.Generator, cells_m, weights):
        cells_m = list(cells_m)
        weights = list(weights)
        if len(cells_m) != len(weights):
            raise ValueError("cells_m and weights must have the same length")
        self.lattice = lattice
        self.octaves = [Octave(rng, c) for c in cells_m]
        self.weights = [float(w) for w in weights]

    def __call__(self, p_m: np.ndarray, footprint_m: np.ndarray | None = None) -> np.ndarray:
        """``p_m`` ``(N, 3)`` metres, ``footprint_m`` ``(N,)`` or None -> ``(N,)`` float32."""
        p_m = np.asarray(p_m)
        if p_m.ndim != 2 or p_m.shape[1] != 3:
            raise ValueError(f"p_m: expected shape (N, 3), got {p_m.shape}")
        return self.eval_T(np.ascontiguousarray(p_m.T, np.float32), footprint_m)

    def eval_T(self, pT: np.ndarray, footprint_m: np.ndarray | None = None) -> np.ndarray:
        """As :meth:`__call__` for points ``pT`` ``(3, N)`` float32 (the fast layout)."""
        N = pT.shape[1]
        out = np.zeros(N, np.float32)
        half = np.float32(0.5)
        fp = None if footprint_m is None else np.asarray(footprint_m, np.float32)
        for oc, w in zip(self.octaves, self.weights):
            w32 = np.float32(w)
            if fp is None:
                v = self.lattice.eval_T(oc.coords_T(pT))
                v -= half
                v *= w32
                out += v
                continue
            lod = lod_weight(oc.cell_m, fp)
            nz = np.count_nonzero(lod)
            if nz == 0:
                continue
            if nz == N:
                v = self.lattice.eval_T(oc.coords_T(pT))
                v -= half
                v *= lod
                v *= w32
                out += v
            else:
                idx = np.flatnonzero(lod)
                v = self.lattice.eval_T(oc.coords_T(np.ascontiguousarray(pT[:, idx])))
                v -= half
                v *= lod[idx]
                v *= w32
                out[idx] += v
        return out


def lod_weight(cell_m: float, footprint_m: np.ndarray) -> np.ndarray:
    """Octave fade ``(N,)`` float32: 1 where a cell spans >= 1.5 footprints, 0 where <= 0.5, linear between."""
    r = np.float32(cell_m) / np.maximum(np.asarray(footprint_m, np.float32), np.float32(1e-9))
    return np.clip(r - np.float32(0.5), 0, 1).astype(np.float32)
