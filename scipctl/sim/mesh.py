"""Triangle-mesh tools for the scene's rocks and pebbles (pure numerics).

Meshes are ``V`` ``(N, 3)`` vertices and ``F`` ``(M, 3)`` vertex indices, consistently
oriented (outward normals by the right-hand rule).
"""

from __future__ import annotations

import numpy as np


def _subdivide(V: np.ndarray, F: np.ndarray):
    """One midpoint subdivision: each triangle -> 4. Returns (V', F')."""
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    e = np.sort(e, axis=1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    mids = 0.5 * (V[uniq[:, 0]] + V[uniq[:, 1]])
    base = len(V)
    nF = len(F)
    m01 = base + inv[:nF]
    m12 = base + inv[nF:2 * nF]
    m20 = base + inv[2 * nF:]
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    F2 = np.concatenate([
        np.stack([a, m01, m20], 1), np.stack([m01, b, m12], 1), np.stack([m20, m12, c], 1), np.stack([m01, m12, m20], 1),
    ])
    return np.concatenate([V, mids]), F2


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals ``(N, 3)`` of a consistently oriented mesh."""
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vn = np.zeros_like(V)
    for k in range(3):
        np.add.at(vn, F[:, k], fn)
    n = np.linalg.norm(vn, axis=1, keepdims=True)
    return vn / np.maximum(n, 1e-30)


def hull_mesh(rng: np.random.Generator, n_points: int, subdiv: int, radius_jitter=(0.72, 1.0)):
    """A faceted unit-scale rock: convex hull of random points, outward-oriented, subdivided.

    Returns ``(V (N, 3), F (M, 3), corner_idx (K,), corner_sharpness (K,))``; corners are the hull
    vertices, ``sharpness`` = angle deficit (rad; high = pointed).
    """
    d = rng.normal(size=(n_points, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    P = d * rng.uniform(*radius_jitter, size=(n_points, 1))
    return hull_of_points(P, subdiv)


def hull_of_points(P: np.ndarray, subdiv: int):
    """The convex hull of points ``P`` ``(n, 3)`` (around the origin), outward-oriented, ``subdiv`` midpoint
    subdivisions: ``(V (N, 3), F (M, 3), corner_idx (K,), corner_sharpness (K,))`` as :func:`hull_mesh`."""
    from scipy.spatial import ConvexHull

    n_points = len(P)
    hull = ConvexHull(P)
    used = np.unique(hull.simplices)
    remap = -np.ones(n_points, int)
    remap[used] = np.arange(len(used))
    V = P[used]
    F = remap[hull.simplices]
    ctr = V.mean(axis=0)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.sum(fn * (V[F].mean(axis=1) - ctr), axis=1) < 0
    F[flip] = F[flip][:, ::-1]
    # angle deficit at the hull vertices
    ang_sum = np.zeros(len(V))
    for k in range(3):
        a = V[F[:, k]]
        b = V[F[:, (k + 1) % 3]] - a
        c = V[F[:, (k + 2) % 3]] - a
        cosang = np.sum(b * c, 1) / (np.linalg.norm(b, axis=1) * np.linalg.norm(c, axis=1))
        np.add.at(ang_sum, F[:, k], np.arccos(np.clip(cosang, -1, 1)))
    sharp = 2 * np.pi - ang_sum
    n_corner = len(V)
    for _ in range(subdiv):
        V, F = _subdivide(V, F)
    return V, F, np.arange(n_corner), sharp
