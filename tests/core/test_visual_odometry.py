"""core/visual_odometry.py: a camera's pose error recovered from 3-D points and their pixels (synthetic scenes with
exact truth, every camera model kind)."""

import numpy as np
import pytest

from scipctl.core.transforms import rotvec_to_matrix
from scipctl.core.visual_odometry import CameraCorrection, camera_axes, camera_correction
from tests.models import all_models, pixel_grid

MODELS = all_models()


def _scene(m, R_true, t_true, n_side=15, seed=3):
    """Pixels of a grid, their true points at 1.5-8 m (the calibrated model sees them there), and where the pose
    estimate puts the same points (the inverse of the correction (R_true, t_true) in the camera frame)."""
    rng = np.random.default_rng(seed)
    uv = pixel_grid(n_side)
    o, d = m.unproject(uv)
    P_true = o + rng.uniform(1.5, 8.0, len(uv))[:, None] * d
    Rc, C = camera_axes(m), np.asarray(m.C, float)
    x_true = (P_true - C) @ Rc.T
    x_est = (x_true - t_true) @ R_true  # R^T (x - t), row-wise
    return uv, x_est @ Rc + C


@pytest.mark.parametrize("name", sorted(MODELS))
def test_a_known_pose_error_is_recovered(name):
    """Noise-free pixels of points whose estimated positions are off by a known camera correction (1.1 deg, 6 cm):
    the fitted correction reproduces every pixel. Central models (CAHV, CAHVOR): to the tolerance of OpenCV's
    Levenberg-Marquardt, which stops when a step of the parameters is below FLT_EPSILON (1.2e-7 rad or m: <= 1.5e-4 px
    at f = 1220 px), bound 1e-3 px and 1e-6 on R and t. CAHVORE's rays are taken at the estimated range, off by the
    correction's share of it: |o - C| (<= 2 mm here) x 6 cm / (1.5 m)^2 x 476 px ~ 0.025 px, bound 0.05 px. Pixels
    whose rays turn behind the camera (the widest CAHVORE's corners) are left out."""
    m = MODELS[name]
    R_true = rotvec_to_matrix(np.radians([0.4, -0.9, 0.5]))
    t_true = np.array([0.03, -0.02, 0.045])
    uv, X_est = _scene(m, R_true, t_true)
    corr = camera_correction(X_est, uv, m, threshold_px=1.0, min_inliers=20)
    assert isinstance(corr, CameraCorrection)
    err = np.abs(m.project(corr.apply(X_est)) - uv).max()
    bound = 0.05 if m.kind == "CAHVORE" else 1e-3
    assert err < bound, f"{name}: {err:.3g} px"
    assert corr.n_inliers == corr.n_points >= 0.95 * len(uv)
    if m.kind != "CAHVORE":
        assert np.allclose(corr.R_camtrue_camest, R_true, atol=1e-6)
        assert np.allclose(corr.t_camtrue_camest_m, t_true, atol=1e-6)
        assert corr.rotation_rad == pytest.approx(np.linalg.norm(np.radians([0.4, -0.9, 0.5])), abs=1e-6)


def test_outliers_are_left_out_and_the_answer_is_repeatable():
    """A third of the pixels moved 20-200 px at random: RANSAC keeps the others, the correction reproduces them
    exactly, and the same call gives the same answer bit for bit (seeded)."""
    m = MODELS["CAHVOR"]
    R_true = rotvec_to_matrix(np.radians([-0.3, 1.4, -0.2]))
    t_true = np.array([-0.05, 0.01, 0.08])
    uv, X_est = _scene(m, R_true, t_true)
    rng = np.random.default_rng(7)
    bad = rng.random(len(uv)) < 1 / 3
    ang = rng.uniform(0, 2 * np.pi, bad.sum())
    uv_obs = uv.copy()
    uv_obs[bad] += rng.uniform(20, 200, bad.sum())[:, None] * np.c_[np.cos(ang), np.sin(ang)]
    a = camera_correction(X_est, uv_obs, m)
    b = camera_correction(X_est, uv_obs, m)
    assert a.n_inliers == (~bad).sum()
    assert np.abs(m.project(a.apply(X_est[~bad])) - uv[~bad]).max() < 1e-3  # LM's tolerance, as above
    assert np.array_equal(a.R_camtrue_camest, b.R_camtrue_camest) and np.array_equal(a.t_camtrue_camest_m,
                                                                                      b.t_camtrue_camest_m)


def test_too_few_agreeing_points_give_none_and_bad_shapes_raise():
    m = MODELS[sorted(MODELS)[0]]
    uv, X_est = _scene(m, np.eye(3), np.zeros(3), n_side=4)  # 16 points
    assert camera_correction(X_est, uv, m, min_inliers=20) is None
    assert camera_correction(X_est, uv, m, min_inliers=10) is not None
    with pytest.raises(ValueError, match="X_rover"):
        camera_correction(X_est[:, :2], uv, m)
    with pytest.raises(ValueError, match="X_rover"):
        camera_correction(X_est, uv[:-1], m)
    with pytest.raises(ValueError, match="threshold_px"):
        camera_correction(X_est, uv, m, threshold_px=0.0)
    with pytest.raises(ValueError, match="X_rover"):
        camera_correction(X_est, uv, m, min_inliers=10).apply(np.zeros(3))


def test_camera_axes_are_a_right_handed_frame_along_the_optical_axis():
    for m in MODELS.values():
        R = camera_axes(m)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
        assert np.allclose(R[2], np.asarray(m.A) / np.linalg.norm(m.A))
