"""Epipolar curves of synthetic CAHV/CAHVOR pairs: every point lies on the left pixel's ray."""

import numpy as np
import pytest

from scipctl.core.epipolar import epipolar_curve
from scipctl.core.triangulation import triangulate_rays
from tests.core.stereo_scenes import make_pair


@pytest.mark.parametrize("kind", ["CAHV", "CAHVOR"])
def test_epipolar_curve_points_lie_on_the_left_ray(kind):
    left, right = make_pair(kind)
    uv = np.array([200.3, 250.8])
    curve, r = epipolar_curve(left, right, uv, 0.5, 50.0)
    assert len(curve) > 10
    assert np.max(np.linalg.norm(np.diff(curve, axis=0), axis=1)) <= 0.5
    o1, d1 = left.unproject(uv[None])
    o2, d2 = right.unproject(curve)
    mid, miss, t = triangulate_rays(o1, d1, o2, d2)
    assert miss.max() < 1e-9 * r.max()
    assert np.allclose(t[:, 0], r, rtol=1e-9)
    # CAHV: a straight line; CAHVOR: a curve (bowed by the radial distortion)
    a, b = curve[0], curve[-1]
    n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
    bow = np.abs((curve - a) @ n).max()
    if kind == "CAHV":
        assert bow < 1e-6
    else:
        assert bow > 0.1
