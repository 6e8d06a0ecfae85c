import warnings

import numpy as np
import pytest

from scipctl.core.camera import cahv_from_intrinsics
from scipctl.core.kinematics import (
    CameraSpec, JointAxis, MastGeometry, RoverConfig, RoverPose, StereoCamera, T_roverB_roverA, model_in_other_pose,
)
from scipctl.core.transforms import (
    RigidTransform, axis_angle_to_matrix, euler_zyx_to_matrix, matrix_to_euler_zyx, matrix_to_quat_wxyz,
    quat_wxyz_to_matrix, rotvec_to_matrix,
)

R_ROVER_CAMFWD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _config(pan_axis=(0, 0, 1), tilt_axis=(0, 1, 0)):
    def cam(y):
        return cahv_from_intrinsics(1200, 1200, 511.5, 511.5, RigidTransform(R_ROVER_CAMFWD, [0.55, y, -1.5]))

    mast = MastGeometry(pan=JointAxis([0.5, 0.0, -1.3], pan_axis), tilt=JointAxis([0.5, 0.0, -1.5], tilt_axis))
    nav = StereoCamera("mast", CameraSpec(cam(-0.1), 1024, 1024), CameraSpec(cam(0.1), 1024, 1024))
    haz = StereoCamera("body", CameraSpec(cam(-0.05), 1024, 1024), CameraSpec(cam(0.05), 1024, 1024))
    return RoverConfig("test", mast, {"navcam": nav, "hazcam": haz})


def test_quaternion_round_trip_and_sign():
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = quat_wxyz_to_matrix(q)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.isclose(np.linalg.det(R), 1.0)
        q2 = matrix_to_quat_wxyz(R)
        assert np.allclose(q2, q * np.sign(q[0]), atol=1e-12)
        assert np.allclose(quat_wxyz_to_matrix(-q), R)  # either sign is valid


def test_rotation_sign_is_right_handed():
    # +90 deg about rover z (down): forward (+x) turns to the right (+y)
    assert np.allclose(axis_angle_to_matrix([0, 0, 1], np.pi / 2) @ [1, 0, 0], [0, 1, 0])
    y, p, r = 0.3, -0.1, 0.05
    assert np.allclose(matrix_to_euler_zyx(euler_zyx_to_matrix(y, p, r)), (y, p, r))


def test_transform_compose_and_invert():
    T_a_b = RigidTransform(rotvec_to_matrix([0.1, 0.2, -0.3]), [1, 2, 3])
    T_b_c = RigidTransform(rotvec_to_matrix([-0.4, 0.0, 0.9]), [-1, 0.5, 2])
    p_c = np.array([[0.3, -0.2, 5.0], [1, 1, 1]])
    assert np.allclose((T_a_b @ T_b_c).apply(p_c), T_a_b.apply(T_b_c.apply(p_c)))
    assert (T_a_b @ T_a_b.inverse()).almost_equal(RigidTransform.identity())
    assert np.allclose(T_a_b.inverse().apply(T_a_b.apply(p_c)), p_c)


def test_head_motion_tilt_first_about_axis_lines():
    cfg = _config()
    pan, tilt = 0.4, -0.3
    M = cfg.mast.head_motion(pan, tilt)
    # explicit: tilt about its line, then pan about its line
    p = np.array([0.7, 0.1, -1.6])
    R_t = axis_angle_to_matrix([0, 1, 0], tilt)
    R_p = axis_angle_to_matrix([0, 0, 1], pan)
    o_t, o_p = np.array([0.5, 0.0, -1.5]), np.array([0.5, 0.0, -1.3])
    q = R_t @ (p - o_t) + o_t
    q = R_p @ (q - o_p) + o_p
    assert np.allclose(M.apply(p), q)
    # points on the pan axis stay put under pan; points on the tilt axis stay put under tilt
    assert np.allclose(cfg.mast.pan.motion(0.7).apply([0.5, 0.0, -3.0]), [0.5, 0.0, -3.0])
    assert np.allclose(cfg.mast.tilt.motion(0.7).apply([0.5, 4.0, -1.5]), [0.5, 4.0, -1.5])


def test_body_camera_ignores_joint_angles():
    cfg = _config()
    assert cfg.camera_model("hazcam", "left", 1.0, 0.5).almost_equal(cfg.camera_model("hazcam", "left"))


@pytest.mark.parametrize("target", [[4.0, 1.0, 0.0], [1.5, -0.8, 0.0], [10.0, 3.0, -0.5], [2.0, 0.0, 0.2]])
@pytest.mark.parametrize("axes", [((0, 0, 1), (0, 1, 0)), ((0.02, -0.01, 1), (0.01, 1, 0.03))])
def test_point_at_centres_the_target(target, axes):
    cfg = _config(*axes)
    pan, tilt = cfg.point_at("navcam", target)
    uv = cfg.camera_model("navcam", "left", pan, tilt).project(np.array([target], float))[0]
    assert np.allclose(uv, [511.5, 511.5], atol=1e-6)
    # and to any requested pixel
    pan2, tilt2 = cfg.point_at("navcam", target, pixel_uv=(300.0, 700.0))
    uv2 = cfg.camera_model("navcam", "left", pan2, tilt2).project(np.array([target], float))[0]
    assert np.allclose(uv2, [300.0, 700.0], atol=1e-6)


def test_point_at_keeps_the_image_upright_for_a_head_whose_zero_pose_looks_down():
    # Mars 2020's RSM: at zero angles the cameras look straight down (A = +z) with the image's down forward (+x)
    # and its right to the rover's left. A target ahead was reached by tilting back over the top: the target centred
    # but the image upside down, the left eye on the rover's right (and Mars 2020's elevation joint past its limit)
    R_rover_camdown = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # columns: h', v', A

    def cam(y):
        return cahv_from_intrinsics(1200, 1200, 511.5, 511.5, RigidTransform(R_rover_camdown, [0.5, y, -1.9]))

    mast = MastGeometry(pan=JointAxis([0.5, 0.0, -1.8], (0, 0, 1)), tilt=JointAxis([0.5, 0.0, -1.9], (0, -1, 0)))
    cfg = RoverConfig("down", mast, {"navcam": StereoCamera("mast", CameraSpec(cam(0.2), 1024, 1024),
                                                            CameraSpec(cam(-0.2), 1024, 1024))})
    for target in ([5.0, 0.5, 0.0], [3.0, -1.0, 0.0], [8.0, 2.0, 0.1]):
        pan, tilt = cfg.point_at("navcam", target)
        left, right = (cfg.camera_model("navcam", eye, pan, tilt) for eye in ("left", "right"))
        assert np.allclose(left.project(np.array([target], float))[0], [511.5, 511.5], atol=1e-6)
        assert left.v_axis[2] > 0.5 and right.v_axis[2] > 0.5  # image down is the world's down (ground ~20-30 deg below)
        # the left eye on the left of the line of sight (the baseline along the image's +u)
        assert np.dot(right.C - left.C, left.h_axis) > 0.39 and -np.pi <= pan < np.pi


def test_point_at_body_camera_is_refused():
    with pytest.raises(ValueError):
        _config().point_at("hazcam", [2.0, 0.0, 0.0])


def test_model_in_other_pose_sees_the_same_site_point():
    cfg = _config()
    pose_a = RoverPose(RigidTransform(euler_zyx_to_matrix(0.3, 0.02, -0.01), [10.0, 5.0, 0.1]))
    pose_b = RoverPose(RigidTransform(euler_zyx_to_matrix(0.5, -0.03, 0.02), [12.0, 6.0, 0.05]))
    m_a = cfg.camera_model("navcam", "left", 0.2, -0.4)  # in rover frame at A
    X_site = pose_a.T_site_rover.apply(m_a.C + 3.0 * m_a.A)
    uv_a = m_a.project(pose_a.T_site_rover.inverse().apply(X_site)[None])
    m_in_b = model_in_other_pose(m_a, pose_a, pose_b)
    uv_b = m_in_b.project(pose_b.T_site_rover.inverse().apply(X_site)[None])
    assert np.allclose(uv_a, uv_b, atol=1e-9)
    T = T_roverB_roverA(pose_b, pose_a)
    assert (T_roverB_roverA(pose_a, pose_b) @ T).almost_equal(RigidTransform.identity())


def test_rover_pose_from_wxyz():
    q = matrix_to_quat_wxyz(euler_zyx_to_matrix(1.0, 0.0, 0.0))
    pose = RoverPose.from_wxyz([1, 2, 3], -q, "odometry", 0.05)
    assert np.allclose(pose.yaw_pitch_roll_rad, (1.0, 0.0, 0.0))
    assert np.allclose(pose.T_site_rover.apply([1.0, 0, 0]), [1 + np.cos(1.0), 2 + np.sin(1.0), 3])


def test_point_at_straight_below_the_head_and_array_initial():
    cfg = _config()
    target = [0.9, 0.2, 0.0]  # steep: ~74 deg below the horizon
    pan, tilt = cfg.point_at("navcam", target)
    uv = cfg.camera_model("navcam", "left", pan, tilt).project(np.array([target], float))[0]
    assert np.allclose(uv, [511.5, 511.5], atol=1e-6)
    # straight under the head (out of reach of this offset camera): a clear error, never NaN angles
    try:
        p2, t2 = cfg.point_at("navcam", [0.5, 0.0, 0.0])
        assert np.isfinite(p2) and np.isfinite(t2)
    except ValueError as e:
        assert "cannot point" in str(e)
    pan2, tilt2 = cfg.point_at("navcam", [4.0, 1.0, 0.0], initial=np.array([0.2, -0.2]))
    uv2 = cfg.camera_model("navcam", "left", pan2, tilt2).project(np.array([[4.0, 1.0, 0.0]]))[0]
    assert np.allclose(uv2, [511.5, 511.5], atol=1e-6)


def test_joint_axis_with_huge_components_is_normalised_without_warnings():
    """|axis| overflowed to inf (a numpy warning), and axis / inf made a zero axis that was accepted."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        j = JointAxis([0.0, 0.0, 0.0], [1e308, 0.0, -1e308])
    np.testing.assert_allclose(j.axis, [np.sqrt(0.5), 0.0, -np.sqrt(0.5)], rtol=1e-15)
    with pytest.raises(ValueError, match="zero-length axis"):
        JointAxis([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
