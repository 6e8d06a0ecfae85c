"""Rotations, quaternions and rigid transforms (scipctl/core/transforms.py).

Exact math: every comparison is at round-off level (1e-12 on unit-size
quantities), against closed forms or scipy.spatial.transform.Rotation.
Frames are named destination first (``T_a_b`` maps frame-b points into a).
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scipctl.core.transforms import (
    RigidTransform,
    axis_angle_to_matrix,
    euler_zyx_to_matrix,
    matrix_to_euler_zyx,
    matrix_to_quat_wxyz,
    matrix_to_rotvec,
    quat_wxyz_to_matrix,
    rotvec_to_matrix,
)

TOL = 1e-12


def _random_quats_wxyz(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _random_transform(rng) -> RigidTransform:
    return RigidTransform(rotvec_to_matrix(rng.uniform(-2.0, 2.0, 3)), rng.uniform(-10.0, 10.0, 3))


def _is_rotation(R):
    return np.allclose(R @ R.T, np.eye(3), atol=TOL) and np.linalg.det(R) == pytest.approx(1.0, abs=TOL)


# ------------------------------------------------------------ quaternions
def test_quat_to_matrix_matches_scipy_batched():
    q = _random_quats_wxyz(50).reshape(5, 10, 4)
    R = quat_wxyz_to_matrix(q)
    assert R.shape == (5, 10, 3, 3)
    ref = Rotation.from_quat(q.reshape(-1, 4)[:, [1, 2, 3, 0]]).as_matrix().reshape(5, 10, 3, 3)  # scipy: (x, y, z, w)
    np.testing.assert_allclose(R, ref, atol=TOL, rtol=0)


def test_quat_to_matrix_normalises_and_ignores_the_sign():
    q = _random_quats_wxyz(1, seed=1)[0]
    R = quat_wxyz_to_matrix(q)
    assert R.shape == (3, 3) and _is_rotation(R)
    np.testing.assert_allclose(quat_wxyz_to_matrix(7.5 * q), R, atol=TOL, rtol=0)
    np.testing.assert_allclose(quat_wxyz_to_matrix(-q), R, atol=TOL, rtol=0)
    # 90 deg about z: (w, x, y, z) = (cos 45, 0, 0, sin 45) maps x to y
    h = np.sqrt(0.5)
    np.testing.assert_allclose(quat_wxyz_to_matrix([h, 0, 0, h]) @ [1.0, 0, 0], [0, 1.0, 0], atol=TOL)


@pytest.mark.parametrize("bad", [np.zeros(4), [1.0, 0, 0], [np.nan, 0, 0, 1.0], [np.inf, 0, 0, 0]])
def test_quat_to_matrix_rejects_bad_quaternions(bad):
    with pytest.raises(ValueError):
        quat_wxyz_to_matrix(bad)


@pytest.mark.parametrize(
    "R",
    [
        axis_angle_to_matrix([0.3, -0.2, 0.9], 0.7),  # trace > 0
        axis_angle_to_matrix([1, 0, 0], 3.0),  # trace < 0, R00 largest
        axis_angle_to_matrix([0, 1, 0], 3.0),  # R11 largest
        axis_angle_to_matrix([0, 0, 1], 3.0),  # R22 largest
        axis_angle_to_matrix([1, 1, 0], np.pi),  # half turn: w = 0
    ],
    ids=["trace>0", "x-dominant", "y-dominant", "z-dominant", "half-turn"],
)
def test_matrix_to_quat_round_trip_every_branch(R):
    q = matrix_to_quat_wxyz(R)
    assert q.shape == (4,)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=TOL)
    assert q[0] >= 0
    np.testing.assert_allclose(quat_wxyz_to_matrix(q), R, atol=TOL, rtol=0)
    ref = Rotation.from_matrix(R).as_quat()[[3, 0, 1, 2]]
    assert min(np.abs(q - ref).max(), np.abs(q + ref).max()) < TOL  # the same up to the sign


def test_quat_matrix_quat_round_trip_keeps_w_non_negative():
    for q in _random_quats_wxyz(200, seed=2):
        back = matrix_to_quat_wxyz(quat_wxyz_to_matrix(q))
        np.testing.assert_allclose(back, q if q[0] >= 0 else -q, atol=TOL, rtol=0)
    with pytest.raises(ValueError):
        matrix_to_quat_wxyz(np.eye(4))


# ------------------------------------------------ axis-angle, rotation vectors
def test_axis_angle_matches_scipy_and_the_right_hand_rule():
    rng = np.random.default_rng(3)
    for _ in range(50):
        axis = rng.normal(size=3) * rng.uniform(0.1, 10.0)  # any length
        ang = rng.uniform(-np.pi, np.pi)
        R = axis_angle_to_matrix(axis, ang)
        ref = Rotation.from_rotvec(axis / np.linalg.norm(axis) * ang).as_matrix()
        np.testing.assert_allclose(R, ref, atol=TOL, rtol=0)
    # right hand: about +z, x goes to y; about +x, y goes to z
    np.testing.assert_allclose(axis_angle_to_matrix([0, 0, 1], np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=TOL)
    np.testing.assert_allclose(axis_angle_to_matrix([1, 0, 0], np.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=TOL)
    with pytest.raises(ValueError):
        axis_angle_to_matrix([0, 0, 0], 1.0)
    with pytest.raises(ValueError):
        axis_angle_to_matrix([0, 1], 1.0)


def test_rotvec_round_trip_and_scipy():
    rng = np.random.default_rng(4)
    for _ in range(50):
        rv = rng.normal(size=3)
        rv *= rng.uniform(0.0, np.pi - 1e-3) / np.linalg.norm(rv)  # angle in [0, pi): a unique rotation vector
        R = rotvec_to_matrix(rv)
        np.testing.assert_allclose(R, Rotation.from_rotvec(rv).as_matrix(), atol=TOL, rtol=0)
        np.testing.assert_allclose(matrix_to_rotvec(R), rv, atol=1e-11, rtol=0)
        np.testing.assert_allclose(matrix_to_rotvec(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-11, rtol=0)
    assert np.array_equal(rotvec_to_matrix(np.zeros(3)), np.eye(3))
    assert np.array_equal(matrix_to_rotvec(np.eye(3)), np.zeros(3))
    with pytest.raises(ValueError):
        rotvec_to_matrix(np.zeros(4))


# ------------------------------------------------------------ Euler angles
def test_euler_zyx_is_intrinsic_yaw_pitch_roll():
    rng = np.random.default_rng(5)
    for _ in range(50):
        yaw, pitch, roll = rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi)
        R = euler_zyx_to_matrix(yaw, pitch, roll)
        np.testing.assert_allclose(R, Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix(), atol=TOL, rtol=0)
        expected = (axis_angle_to_matrix([0, 0, 1], yaw) @ axis_angle_to_matrix([0, 1, 0], pitch)
                    @ axis_angle_to_matrix([1, 0, 0], roll))
        np.testing.assert_allclose(R, expected, atol=TOL, rtol=0)
        back = matrix_to_euler_zyx(R)
        assert isinstance(back, tuple) and len(back) == 3
        np.testing.assert_allclose(back, (yaw, pitch, roll), atol=1e-10, rtol=0)


# --------------------------------------------------------- RigidTransform
def test_rigid_transform_checks_and_converts_its_fields():
    T = RigidTransform(np.eye(3, dtype=int), [1, 2, 3])
    assert T.R.dtype == float and T.t.dtype == float and T.t.shape == (3,)
    with pytest.raises(ValueError):
        RigidTransform(np.eye(4), np.zeros(3))
    with pytest.raises(ValueError):
        RigidTransform(np.eye(3), np.zeros(4))
    with pytest.raises(ValueError):
        RigidTransform.from_matrix(np.eye(3))
    with pytest.raises(ValueError):
        RigidTransform.from_quat_wxyz([1.0, 0, 0, 0], np.zeros(2))


def test_identity_matrix_and_quaternion_round_trips():
    rng = np.random.default_rng(6)
    I = RigidTransform.identity()
    assert np.array_equal(I.R, np.eye(3)) and np.array_equal(I.t, np.zeros(3))
    T_a_b = _random_transform(rng)
    M = T_a_b.matrix
    assert M.shape == (4, 4) and np.array_equal(M[3], [0, 0, 0, 1])
    assert RigidTransform.from_matrix(M).almost_equal(T_a_b, tol=0.0)
    q = T_a_b.quat_wxyz
    assert q.shape == (4,) and q[0] >= 0
    assert RigidTransform.from_quat_wxyz(q, T_a_b.t).almost_equal(T_a_b, tol=TOL)
    # the homogeneous matrix acts like apply
    p_b = rng.normal(size=(7, 3))
    ph = np.c_[p_b, np.ones(7)] @ M.T
    np.testing.assert_allclose(ph[:, :3], T_a_b.apply(p_b), atol=TOL, rtol=0)


@pytest.mark.parametrize("shape", [(3,), (1, 3), (8, 3), (2, 5, 3)])
def test_apply_and_rotate_keep_the_shape(shape):
    rng = np.random.default_rng(7)
    T_a_b = _random_transform(rng)
    p_b = rng.normal(size=shape)
    p_a = T_a_b.apply(p_b)
    v_a = T_a_b.rotate(p_b)
    assert p_a.shape == shape and v_a.shape == shape
    flat = p_b.reshape(-1, 3)
    np.testing.assert_allclose(p_a.reshape(-1, 3), np.array([T_a_b.R @ p + T_a_b.t for p in flat]), atol=TOL, rtol=0)
    np.testing.assert_allclose(v_a.reshape(-1, 3), np.array([T_a_b.R @ p for p in flat]), atol=TOL, rtol=0)
    # rotate ignores the translation: it is apply minus the image of the origin
    np.testing.assert_allclose(v_a, p_a - T_a_b.apply(np.zeros(3)), atol=1e-11, rtol=0)
    # against scipy (rotation part)
    ref = Rotation.from_matrix(T_a_b.R).apply(flat).reshape(shape)
    np.testing.assert_allclose(v_a, ref, atol=TOL, rtol=0)


def test_apply_and_rotate_reject_non_3d_points():
    T = RigidTransform.identity()
    for bad in (np.zeros(2), np.zeros((4, 2)), np.zeros((3, 4))):
        with pytest.raises(ValueError):
            T.apply(bad)
        with pytest.raises(ValueError):
            T.rotate(bad)


def test_apply_does_not_modify_its_input():
    rng = np.random.default_rng(8)
    T = _random_transform(rng)
    p = rng.normal(size=(4, 3))
    keep = p.copy()
    T.apply(p)
    T.rotate(p)
    assert np.array_equal(p, keep)


def test_inverse_undoes_the_transform():
    rng = np.random.default_rng(9)
    for _ in range(20):
        T_a_b = _random_transform(rng)
        T_b_a = T_a_b.inverse()
        assert _is_rotation(T_b_a.R)
        p_b = rng.normal(size=(10, 3))
        np.testing.assert_allclose(T_b_a.apply(T_a_b.apply(p_b)), p_b, atol=1e-11, rtol=0)
        assert (T_a_b @ T_b_a).almost_equal(RigidTransform.identity(), tol=1e-12)
        assert (T_b_a @ T_a_b).almost_equal(RigidTransform.identity(), tol=1e-12)
        assert T_b_a.inverse().almost_equal(T_a_b, tol=1e-12)
        np.testing.assert_allclose(T_b_a.matrix, np.linalg.inv(T_a_b.matrix), atol=1e-12, rtol=0)


def test_composition_inner_frames_cancel():
    rng = np.random.default_rng(10)
    T_site_rover, T_rover_head, T_head_navcam = (_random_transform(rng) for _ in range(3))
    p_navcam = rng.normal(size=(6, 3))
    T_site_navcam = T_site_rover @ T_rover_head @ T_head_navcam
    np.testing.assert_allclose(
        T_site_navcam.apply(p_navcam),
        T_site_rover.apply(T_rover_head.apply(T_head_navcam.apply(p_navcam))),
        atol=1e-11, rtol=0,
    )
    # associativity, and the matrix product
    other = T_site_rover @ (T_rover_head @ T_head_navcam)
    assert other.almost_equal(T_site_navcam, tol=1e-12)
    np.testing.assert_allclose(
        T_site_navcam.matrix, T_site_rover.matrix @ T_rover_head.matrix @ T_head_navcam.matrix, atol=1e-11, rtol=0
    )
    # (T_a_b @ T_b_c)^-1 = T_c_b @ T_b_a
    T_navcam_site = T_head_navcam.inverse() @ T_rover_head.inverse() @ T_site_rover.inverse()
    assert T_site_navcam.inverse().almost_equal(T_navcam_site, tol=1e-12)
    # a frame and its inverse cancel: T_site_rover @ T_rover_site @ T_site_navcam == T_site_navcam
    assert (T_site_rover @ T_site_rover.inverse() @ T_site_navcam).almost_equal(T_site_navcam, tol=1e-11)
    assert T_site_rover.__matmul__(np.eye(4)) is NotImplemented  # only transforms compose
    with pytest.raises(TypeError):
        T_site_rover @ "T_rover_head"


def test_rotation_about_line_fixes_the_line():
    axis, origin = np.array([0.0, 0.0, 2.0]), np.array([1.0, -2.0, 0.5])
    T = RigidTransform.rotation_about_line(axis, origin, np.pi / 2)
    on_line = origin + np.outer([-1.5, 0.0, 3.0], axis)
    np.testing.assert_allclose(T.apply(on_line), on_line, atol=TOL, rtol=0)
    # a point 1 m off the line along +x goes to 1 m along +y (right hand about +z)
    np.testing.assert_allclose(T.apply(origin + [1.0, 0, 0]), origin + [0, 1.0, 0], atol=TOL, rtol=0)
    assert T.rotation_angle_rad() == pytest.approx(np.pi / 2, abs=TOL)


def test_almost_equal_and_rotation_angle():
    T = RigidTransform(axis_angle_to_matrix([1, 2, 3], 0.4), np.array([1.0, 2.0, 3.0]))
    assert T.rotation_angle_rad() == pytest.approx(0.4, abs=TOL)
    assert RigidTransform.identity().rotation_angle_rad() == 0.0
    # near zero (np.allclose's relative term, 1e-5 of the value, vanishes there) tol is the absolute bound
    I = RigidTransform.identity()
    moved = RigidTransform(np.eye(3), np.array([0.0, 0.0, 1e-6]))
    assert I.almost_equal(moved, tol=1e-5)
    assert not I.almost_equal(moved, tol=1e-9)
    turned = RigidTransform(axis_angle_to_matrix([0, 0, 1], 1e-6), np.zeros(3))
    assert I.almost_equal(turned, tol=1e-5)
    assert not I.almost_equal(turned, tol=1e-9)
