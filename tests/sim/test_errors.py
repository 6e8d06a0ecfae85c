"""The injected errors are the errors present, in the amounts configured."""

import numpy as np
import pytest

from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix, euler_zyx_to_matrix, matrix_to_euler_zyx
from scipctl.sim.errors import DEG, ErrorSettings, estimate_poses, true_rover_config, vibration
from scipctl.sim.rover import default_rover_config
from scipctl.sim.build import build_run

from .conftest import SMALL

ANGLES = [(0.0, 0.0), (0.3, -0.5), (-1.2, -0.9), (2.5, 0.4)]


def _only(**kw):
    return ErrorSettings(**{**ErrorSettings.none().__dict__, **kw})


def test_no_errors_true_config_equals_calibrated():
    cal = default_rover_config()
    tru = true_rover_config(cal, ErrorSettings.none())
    for cam in cal.cameras:
        for eye in ("left", "right"):
            for pan, tilt in ANGLES:
                assert tru.camera_model(cam, eye, pan, tilt).almost_equal(cal.camera_model(cam, eye, pan, tilt), 1e-12)


def test_true_mast_is_offset_encoders_on_a_skewed_displaced_tilt_axis():
    """Independent composition: Rot(pan axis, pan + dp) . Rot(tilt' axis, tilt + dt) . displacement, applied to m0."""
    cal = default_rover_config()
    e = _only(mast_tilt_offset_rad=-1.0 * DEG, mast_pan_offset_rad=0.4 * DEG, mast_tilt_axis_error_rad=0.5 * DEG,
              mast_head_offset_m=(0.004, -0.003, 0.002))
    tru = true_rover_config(cal, e)
    pan_o, pan_a = cal.mast.pan.origin_m, cal.mast.pan.axis
    off = np.array(e.mast_head_offset_m)
    tilt_o = cal.mast.tilt.origin_m + off
    tilt_a = axis_angle_to_matrix(pan_a, e.mast_tilt_axis_error_rad) @ cal.mast.tilt.axis
    for pan, tilt in ANGLES:
        M = (RigidTransform.rotation_about_line(pan_a, pan_o, pan + e.mast_pan_offset_rad)
             @ RigidTransform.rotation_about_line(tilt_a, tilt_o, tilt + e.mast_tilt_offset_rad)
             @ RigidTransform(np.eye(3), off))
        for cam in ("pancam", "navcam"):
            for eye in ("left", "right"):
                want = cal.spec(cam, eye).model.transformed(M)
                assert tru.camera_model(cam, eye, pan, tilt).almost_equal(want, 1e-12)
        # body cameras do not move with the mast
        assert tru.camera_model("hazcam", "left", pan, tilt).almost_equal(cal.camera_model("hazcam", "left"), 0)


@pytest.mark.parametrize("tilt_err_deg", [-1.0, 0.5])
def test_mast_tilt_error_displaces_navcam_marks_by_the_expected_pixels(tilt_err_deg):
    """Project the targets through the calibrated (product) and true models of the near navcam and hazcam.

    The displacement is that of the camera turned by the tilt error about a horizontal axis through its own
    centre (the tilt axis is ~8 cm away, which adds a small parallax term at 2 m), i.e. ~21 px per degree
    at 0.82 mrad/px, along v: a head that really looks lower shows the scene higher up.
    """
    e = _only(mast_tilt_offset_rad=tilt_err_deg * DEG)
    sim = build_run("paper", "s1-straight", 1, errors=e, render=False)
    dl = sim.downlink
    delta = tilt_err_deg * DEG
    cal = dl.rover_config
    for cam, eye in (("navcam", "left"), ("navcam", "right"), ("hazcam", "left")):
        im = dl.product(f"s1-straight-near-{cam}-{eye[0].upper()}")
        tr = dl.truth_for(im.product_id)
        for t in dl.truth_targets:
            X = tr.pose.T_site_rover.inverse().apply(t.xyz_site_m[None])
            d = tr.camera_model.project(X)[0] - im.camera_model.project(X)[0]
            if cam == "hazcam":
                assert np.allclose(d, 0.0, atol=1e-9)  # body-mounted: no mast error
                continue
            # the same camera, rotated by delta about the (panned) tilt-axis direction through its own centre
            axis = cal.mast.pan.motion(im.mast.pan_rad).rotate(cal.mast.tilt.axis)
            turned = im.camera_model.transformed(RigidTransform.rotation_about_line(axis, im.camera_model.C, delta))
            d_rot = turned.project(X)[0] - im.camera_model.project(X)[0]
            assert np.linalg.norm(d - d_rot) < 0.06 * np.linalg.norm(d_rot)
            assert d[1] == pytest.approx(delta / 0.82e-3, rel=0.15)
            assert np.sign(d[1]) == np.sign(delta) and abs(d[0]) < 0.1 * abs(d[1])


def test_pose_estimate_exact_without_errors_and_drifting_with_them():
    yaws = [0.0, 0.2, 0.1, -0.3]
    T = [RigidTransform(euler_zyx_to_matrix(y, 0.02 * k, -0.01 * k), np.array([2.0 * k, 0.5 * k * k, -0.1 * k]))
         for k, y in enumerate(yaws)]
    L = [0.0] + [float(np.linalg.norm(T[k].t - T[k - 1].t)) for k in range(1, 4)]
    turns = [0.0] + [yaws[k] - yaws[k - 1] for k in range(1, 4)]
    est, rec = estimate_poses(T, L, turns, ErrorSettings.none(), np.random.default_rng(0))
    assert rec["exact"] and all(np.array_equal(a.R, b.R) and np.array_equal(a.t, b.t) for a, b in zip(est, T))
    # distance scale only: every leg is the true one scaled by the recorded factor, headings exact
    est, rec = estimate_poses(T, L, turns, _only(odometry_scale_sigma=0.05, odometry_scale_leg_sigma=0.02),
                              np.random.default_rng(1))
    assert np.array_equal(est[0].t, T[0].t)
    for k in range(1, 4):
        d_true = T[k - 1].inverse().apply(T[k].t)
        d_est = est[k - 1].inverse().apply(est[k].t)
        assert np.allclose(d_est, rec["legs"][k - 1]["distance_scale"] * d_true, atol=1e-12)
        assert np.allclose(est[k].R, T[k].R, atol=1e-12)
    # heading drift only: the yaw error is the sum of the recorded per-leg errors
    est, rec = estimate_poses(T, L, turns, _only(heading_drift_sigma_rad_per_m=1.0 * DEG, heading_noise_sigma_rad=0.5 * DEG),
                              np.random.default_rng(2))
    acc = 0.0
    for k in range(1, 4):
        acc += rec["legs"][k - 1]["yaw_error_added_rad"]
        dy = matrix_to_euler_zyx(est[k].R)[0] - matrix_to_euler_zyx(T[k].R)[0]
        assert (dy - acc + np.pi) % (2 * np.pi) - np.pi == pytest.approx(0.0, abs=1e-12)
    assert abs(acc) > 1e-4
    # lateral position error appears once the heading is wrong
    assert np.linalg.norm(est[-1].t[:2] - T[-1].t[:2]) > 1e-3


def test_vibration_epipolar_offset_sizes():
    """Right-eye vibration (1.1 mrad max) moves pancam points by up to ~4 px and navcam points by ~1/3 of that."""
    e = _only(vibration_max_rad=1.1e-3)
    sim = build_run("paper", "s1-straight", 1, errors=e, render=False)
    dl = sim.downlink
    worst = {"pancam": 0.0, "navcam": 0.0, "hazcam": 0.0}
    for im in dl.images:
        tr = dl.truth_for(im.product_id)
        X = tr.camera_model.C + 5.0 * tr.camera_model.A  # a point on the boresight
        d = np.linalg.norm(tr.camera_model.project(X[None])[0] - im.camera_model.project(X[None])[0])
        if im.eye == "left":
            assert d < 1e-9
        worst[im.camera] = max(worst[im.camera], d)
    assert 0.3 * 1.1e-3 / 0.28e-3 * 0.2 < worst["pancam"] <= 1.1e-3 / 0.28e-3 * 1.02
    assert worst["navcam"] <= 1.1e-3 / 0.82e-3 * 1.02
    assert worst["hazcam"] == 0.0
    # every pair's realised rotation is recorded, and its size is within the configured range
    for s in sim.record["stops"]:
        for pr in s["pairs"]:
            a = np.linalg.norm(pr["vibration_rotvec_rad"])
            assert (0.3 * 1.1e-3 - 1e-12 <= a <= 1.1e-3 + 1e-12) if pr["camera"] != "hazcam" else a == 0.0


def test_vibration_is_a_rotation_about_the_pivot():
    T, rv = vibration(np.random.default_rng(3), 2e-3, [0.3, 0.0, -1.5])
    assert np.allclose(T.apply([0.3, 0.0, -1.5]), [0.3, 0.0, -1.5])
    assert 0.6e-3 <= np.linalg.norm(rv) <= 2e-3
    assert T.rotation_angle_rad() == pytest.approx(np.linalg.norm(rv))


@pytest.mark.parametrize("kind,scale", [("baseline", 1.05), ("focal", 0.97)])
def test_stale_calibration_biases_stereo_range(kind, scale):
    """Triangulating the true projections with the calibrated models scales the range by 1/scale."""
    kw = {"stale_camera": "navcam", ("stale_baseline_scale" if kind == "baseline" else "stale_focal_scale"): scale}
    e = _only(**kw)
    cal = default_rover_config()
    tru = true_rover_config(cal, e)
    pan, tilt = cal.point_at("navcam", [3.0, 0.3, 0.0])
    tl, trr = tru.camera_model("navcam", "left", pan, tilt), tru.camera_model("navcam", "right", pan, tilt)
    cl, cr = cal.camera_model("navcam", "left", pan, tilt), cal.camera_model("navcam", "right", pan, tilt)
    ratios = []
    for X in ([3.0, 0.3, 0.0], [2.5, -0.4, -0.1], [4.0, 0.8, 0.05]):
        X = np.array(X)
        ul, ur = tl.project(X[None]), trr.project(X[None])
        o1, d1 = cl.unproject(ul)
        o2, d2 = cr.unproject(ur)
        # closest point of the two rays
        w = o1[0] - o2[0]
        a, b, c, dd, ee = d1[0] @ d1[0], d1[0] @ d2[0], d2[0] @ d2[0], d1[0] @ w, d2[0] @ w
        s = (b * ee - c * dd) / (a * c - b * b)
        P = o1[0] + s * d1[0]
        ratios.append(np.linalg.norm(P - cl.C) / np.linalg.norm(X - tl.C))
    assert np.allclose(ratios, 1.0 / scale, rtol=0.01)


def test_gain_differences_and_no_error_gains():
    e = ErrorSettings()
    assert e.responsivity_of("hazcam", "left") < e.responsivity_of("navcam", "left")
    assert e.responsivity_of("navcam", "right") != e.responsivity_of("navcam", "left")
    n = ErrorSettings.none()
    assert all(n.responsivity_of(c, s) == 1.0 for c in ("pancam", "navcam", "hazcam") for s in ("left", "right"))


def test_hazcam_darker_than_navcam_in_rendered_products(run_errors):
    """Auto-exposure for a nominal camera + true responsivity 0.6: hazcam images come out darker."""
    dl = run_errors.downlink
    mean = {im.product_id: float(im.pixels_float().mean()) for im in dl.images}
    assert mean["s1-straight-near-hazcam-L"] < 0.8 * mean["s1-straight-near-navcam-L"]


def test_small_scale_error_free_run_has_exact_pointing(run_exact):
    # (the error-free case: pointing exact; with errors the pointing is off by the mast error)
    sim = build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, render=False)
    aim = sim.scene.target_rock.aim_point_site()
    off = []
    for p in sim.products:
        if p.camera == "navcam" and p.eye == "left":
            uv = p.model_true_site.project(aim[None])[0]
            off.append(uv - [(p.width - 1) / 2, (p.height - 1) / 2])
    # -1 deg tilt error at 8x the navcam IFOV (128 px images): ~2.7 px upwards, plus pointing noise
    assert all(o[1] < -1.0 for o in off)


def test_error_scale_multiplies_the_magnitudes():
    from scipctl.sim.scenarios import default_errors

    base = default_errors("paper")
    assert base.scaled(0.0) == ErrorSettings.none() and base.scaled(1.0) is base
    for s in (0.5, 2.0):
        e = base.scaled(s)
        assert e.mast_tilt_offset_rad == pytest.approx(s * base.mast_tilt_offset_rad)
        assert e.mast_head_offset_m == pytest.approx(tuple(s * v for v in base.mast_head_offset_m))
        assert e.odometry_scale_sigma == pytest.approx(s * base.odometry_scale_sigma)
        assert e.vibration_max_rad == pytest.approx(s * base.vibration_max_rad)
        assert e.pointing_noise_frac == pytest.approx(s * base.pointing_noise_frac)
        # multiplicative errors in log space: twice the error is the gain applied twice
        assert e.responsivity["hazcam"] == pytest.approx(tuple(r ** s for r in base.responsivity["hazcam"]))
        assert e.washed_out_factor == pytest.approx(base.washed_out_factor ** s)
        assert e.washed_out == base.washed_out and e.sensor_noise
    with pytest.raises(ValueError):
        base.scaled(2.5)
