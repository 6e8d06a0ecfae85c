"""Rock shapes and rocks on the terrain (scipctl/sim/rocks.py)."""

import numpy as np
import pytest

from scipctl.sim.noise import LatticeNoise
from scipctl.sim.rocks import ROCK_SHAPES, make_rock
from scipctl.sim.terrain import random_height_field


def _closed_outward(V, F):
    vol = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    return vol > 0 and len({tuple(x) for x in e.tolist()}) == len(e) and len({tuple(sorted(x)) for x in e.tolist()}) == len(e) // 2


@pytest.mark.parametrize("name", list(ROCK_SHAPES))
def test_each_shape_makes_a_closed_outward_mesh_and_a_rock_of_the_asked_size(name):
    shape = ROCK_SHAPES[name].check()
    V, F, corners, sharp = shape.unit_mesh(np.random.default_rng(3), 24, 2)
    assert _closed_outward(V - V.mean(axis=0), F) and len(corners) == len(sharp) and np.all(corners < len(V))
    rng = np.random.default_rng(8)
    field = random_height_field(rng)
    size = np.array([0.5, 0.4, 0.3 * shape.height_scale])
    r = make_rock("r", rng, LatticeNoise(rng, 32), field, (1.0, 2.0), size, 24, 3, 0.012, 1.0, shape=shape)
    # the unit mesh spans [-1, 1] on each axis before roughness, yaw and lean: the rock's horizontal diameter lies
    # between its length and the diagonal of length x width (5 % for the roughness and the small lean)
    from scipy.spatial import ConvexHull

    hxy = r.vertices[ConvexHull(r.vertices[:, :2]).vertices, :2]
    diam = np.sqrt(((hxy[:, None] - hxy[None]) ** 2).sum(-1)).max()
    assert 0.5 * 0.95 <= diam <= np.hypot(0.5, 0.4) * 1.05
    assert r.size_m[2] == pytest.approx(size[2], rel=0.25)
    g = field.height_m(np.array([[1.0, 2.0]]))[0]
    assert -r.vertices[:, 2].max() < g  # partly buried: the bottom is below the ground


def test_shapes_differ_in_corners():
    """Angular blocks have few, sharp corners; rounded boulders many blunt ones; both differ from faceted hulls."""
    stats = {}
    for name, shape in ROCK_SHAPES.items():
        sh = [shape.unit_mesh(np.random.default_rng(s), 30, 0)[3] for s in range(10)]
        stats[name] = (np.mean([len(x) for x in sh]), np.mean([x.max() for x in sh]))
    assert stats["angular"][0] < 0.7 * stats["faceted"][0]
    assert stats["rounded"][0] > 2 * stats["faceted"][0] and stats["rounded"][1] < 0.5 * stats["faceted"][1]
