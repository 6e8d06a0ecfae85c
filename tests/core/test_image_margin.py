"""scipctl.core.image_margin: the margin of points inside both images of a body-fixed pair (exact truth on a
pinhole pair)."""

import numpy as np
import pytest

from scipctl.core.camera import cahv_from_intrinsics
from scipctl.core.image_margin import pair_margin_px
from scipctl.core.kinematics import CameraSpec, JointAxis, MastGeometry, RoverConfig, StereoCamera
from scipctl.core.transforms import RigidTransform

R_ROVER_CAMFWD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # camera z = rover x (forward)
F_PX, W, H = 1000.0, 1024, 768


def _rover(cx=511.5, cy=383.5):
    def cam(y):
        return CameraSpec(cahv_from_intrinsics(F_PX, F_PX, cx, cy, RigidTransform(R_ROVER_CAMFWD, [0.5, y, -1.0])), W, H)

    mast = MastGeometry(pan=JointAxis([0.5, 0.0, -1.3], [0, 0, 1]), tilt=JointAxis([0.5, 0.0, -1.5], [0, 1, 0]))
    return RoverConfig("test", mast, {"hazcam": StereoCamera("body", cam(-0.1), cam(0.1))})


def test_margin_of_points_on_a_pinhole_pair_is_their_distance_to_the_nearer_edge_of_either_image():
    rc = _rover()
    # a point straight ahead of the pair's midpoint, 2 m in front: u = 511.5 -+ 1000 * 0.1 / 2 in the two eyes
    X = np.array([[2.5, 0.0, -1.0]])
    u_left, u_right = 511.5 + F_PX * 0.1 / 2.0, 511.5 - F_PX * 0.1 / 2.0
    want = min(383.5, W - 1 - u_left, u_right)
    assert pair_margin_px(rc, "hazcam", X)[0] == pytest.approx(want, abs=1e-9)
    # moved down (rover +z) until its image row is 10 px below the bottom edge: -10
    dz = (H - 1 - 383.5 + 10.0) / F_PX * 2.0
    assert pair_margin_px(rc, "hazcam", X + [0.0, 0.0, dz])[0] == pytest.approx(-10.0, abs=1e-9)


def test_points_behind_the_pair_or_a_missing_camera_have_no_margin():
    rc = _rover()
    X = np.array([[2.5, 0.0, -1.0], [-1.0, 0.0, -1.0]])
    m = pair_margin_px(rc, "hazcam", X)
    assert np.isfinite(m[0]) and m[1] == -np.inf
    assert np.all(pair_margin_px(rc, "navcam", X) == -np.inf)
    with pytest.raises(ValueError, match="xyz_rover"):
        pair_margin_px(rc, "hazcam", np.zeros(3))
