"""The terrain's height field and graded grid (scipctl/sim/terrain.py)."""

import numpy as np

from scipctl.sim.terrain import graded_axis, grid_mesh, random_height_field


def test_height_field_gradient_graded_axis_and_grid_mesh():
    f = random_height_field(np.random.default_rng(5))
    g = random_height_field(np.random.default_rng(5))
    assert np.array_equal(f.wavevectors, g.wavevectors)
    xy = np.random.default_rng(0).uniform(-3, 3, (200, 2))
    h, grad = f.height_and_gradient(xy)
    eps = 1e-6
    fd = np.stack([(f.height_m(xy + [eps, 0]) - f.height_m(xy - [eps, 0])) / (2 * eps),
                   (f.height_m(xy + [0, eps]) - f.height_m(xy - [0, eps])) / (2 * eps)], 1)
    assert np.allclose(grad, fd, atol=1e-7)
    ax = graded_axis()
    assert np.allclose(np.diff(ax[np.abs(ax) <= 4.0]), 0.02)
    assert np.all(np.diff(ax) > 0) and ax[-1] == 150.0 and ax[0] == -150.0
    xyg, tris, sp = grid_mesh(ax[:5], ax[:4])
    assert len(xyg) == 20 and len(tris) == 2 * 4 * 3
