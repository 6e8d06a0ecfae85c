"""Ray triangulation (closest approach): exact intersections, skew and parallel rays."""

import numpy as np
import pytest

from scipctl.core.triangulation import triangulate_rays


def test_triangulate_rays_exact_and_skew():
    rng = np.random.default_rng(0)
    X = rng.uniform(-5, 5, (20, 3))
    o1 = rng.uniform(-1, 1, (20, 3))
    o2 = rng.uniform(-1, 1, (20, 3))
    d1 = (X - o1) * rng.uniform(0.3, 2.0, (20, 1))  # any length
    d2 = X - o2
    mid, miss, t = triangulate_rays(o1, d1, o2, d2)
    assert mid.shape == (20, 3) and miss.shape == (20,) and t.shape == (20, 2)
    assert np.abs(mid - X).max() < 1e-9
    assert miss.max() < 1e-9
    assert np.allclose(o1 + t[:, :1] * d1, X)
    # skew lines: x axis and a line parallel to y at z = 2: distance 2, midpoint (3, 0, 1)
    mid, miss, t = triangulate_rays([0, 0, 0], [1, 0, 0], [3, 5, 2], [0, -1, 0])
    assert miss == pytest.approx(2.0)
    assert np.allclose(mid, [3, 0, 1])
    assert np.allclose(t, [3, 5])
    # parallel rays: NaN
    mid, miss, t = triangulate_rays([0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 0, 2])
    assert np.all(np.isnan(mid)) and np.all(np.isnan(t))
    with pytest.raises(ValueError):
        triangulate_rays(np.zeros(2), np.ones(3), np.zeros(3), np.ones(3))
