"""Hull meshes for rocks and pebbles (scipctl/sim/mesh.py)."""

import numpy as np

from scipctl.sim.mesh import hull_mesh


def test_hull_mesh_is_closed_and_outward_oriented():
    V, F, corners, sharp = hull_mesh(np.random.default_rng(6), 20, 2)
    # closed, outward-oriented: positive volume, every edge used twice (once per direction)
    vol = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6
    assert vol > 0
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    assert len({tuple(x) for x in e.tolist()}) == len(e)
    assert len({tuple(sorted(x)) for x in e.tolist()}) == len(e) // 2
    assert np.all(sharp > 0) and len(corners) == len(sharp)
