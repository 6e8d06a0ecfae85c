"""The planes the chain's feature step renders through (pipeline/plane_warp.render_planes); the rendering itself is
tested through the chain (test_chain.py) and the feature step (test_feature_track.py)."""

from types import SimpleNamespace

import numpy as np

from scipctl.core.transforms import RigidTransform
from scipctl.pipeline.plane_warp import GROUND_PLANE_MIN_DEG, render_planes


def _prod(yaw_rad=0.0, roll_rad=0.0):
    """A stand-in image product: only its pose estimate is read (site <- rover, rotation about x then z)."""
    cx, sx, cz, sz = np.cos(roll_rad), np.sin(roll_rad), np.cos(yaw_rad), np.sin(yaw_rad)
    R_site_rover = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1.0]]) @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R_site_rover, [3.0, -2.0, 0.5]
    return SimpleNamespace(pose=SimpleNamespace(T_site_rover=RigidTransform.from_matrix(M)))


def _tilted(deg):
    """A unit normal ``deg`` degrees from site -z (the ground's up in the rover frames: +z is down)."""
    a = np.radians(deg)
    return np.array([np.sin(a), 0.0, -np.cos(a)])


def test_the_target_surface_first_and_the_ground_when_it_differs():
    prod = _prod(0.3)
    own, ground = _tilted(30.0), _tilted(2.0)
    planes, n_view = render_planes(prod, own, ground)
    assert n_view is own and len(planes) == 2 and planes[0] is own and planes[1] is ground
    # within GROUND_PLANE_MIN_DEG of each other: one plane (28 deg apart above, 4 deg here)
    planes, n_view = render_planes(prod, _tilted(6.0), ground)
    assert GROUND_PLANE_MIN_DEG == 5.0 and len(planes) == 1 and np.allclose(planes[0], _tilted(6.0))


def test_without_a_local_normal_the_ground_then_the_rover_down_axis():
    prod = _prod(0.3, roll_rad=0.2)
    ground = _tilted(10.0)
    planes, n_view = render_planes(prod, None, ground)
    assert n_view is ground and len(planes) == 1
    planes, n_view = render_planes(prod, None, None)
    # the rover's up (-z, rover frame) in the site frame: tilted by the roll, then turned by the yaw
    tilted = np.array([0.0, np.sin(0.2), -np.cos(0.2)])
    expected = np.array([-np.sin(0.3) * tilted[1], np.cos(0.3) * tilted[1], tilted[2]])
    assert len(planes) == 1 and np.allclose(n_view, expected, atol=1e-12)
