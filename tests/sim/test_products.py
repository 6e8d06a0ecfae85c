"""The images of a run: stops, times, poses, pointing and injected errors (scipctl/sim/products.py)."""

import numpy as np
import pytest


def test_products_stops_times_and_poses(run_errors):
    dl = run_errors.downlink
    ims = sorted(dl.images, key=lambda i: i.time_s)
    assert [i.product_id for i in ims] == [i.product_id for i in dl.images]
    t = [i.time_s for i in ims]
    assert all(b > a for a, b in zip(t, t[1:])), "time_s strictly increasing"
    plan = run_errors.plan
    assert dl.positions() == [(1, k) for k in range(len(plan.stops))]
    for k, stop in enumerate(plan.stops):
        at = dl.images_at((1, k))
        assert sorted({i.camera for i in at}) == sorted(stop.cameras)
        assert all(np.array_equal(i.pose.T_site_rover.t, at[0].pose.T_site_rover.t) for i in at), "one pose per stop"
        for im in at:
            assert (im.mast is not None) == (im.camera != "hazcam")
            assert im.width == im.height == 128
            assert im.pixels.shape == (128, 128)
    assert len(dl.truth_images) == len(dl.images)


def test_no_errors_means_exact_models_and_poses(run_exact):
    dl = run_exact.downlink
    for im in dl.images:
        tr = dl.truth_for(im.product_id)
        assert np.array_equal(im.pose.T_site_rover.R, tr.pose.T_site_rover.R)
        assert np.array_equal(im.pose.T_site_rover.t, tr.pose.T_site_rover.t)
        assert im.camera_model.almost_equal(tr.camera_model, 1e-12)
    # and the mast cameras are pointed exactly at the rock's aim point
    aim = run_exact.scene.target_rock.aim_point_site()
    for p in run_exact.products:
        if p.pan_rad is not None and p.eye == "left":
            uv = p.model_true_site.project(aim[None])[0]
            assert np.allclose(uv, [(p.width - 1) / 2, (p.height - 1) / 2], atol=1e-6)


def test_errors_are_present_where_configured(run_errors):
    dl = run_errors.downlink
    rec = run_errors.record
    # pose error grows from exact at the first stop
    errs = [s["position_error_m"] for s in rec["stops"]]
    assert errs[0] == 0.0 and errs[-1] > 0.01
    for im in dl.images:
        tr = dl.truth_for(im.product_id)
        same = im.camera_model.almost_equal(tr.camera_model, 1e-9)
        assert same == (im.camera == "hazcam"), im.product_id  # mast calibration error on mast cameras only
    # the washed-out pair is not in this run; the gains differ between cameras
    resp = {r["product_id"]: r["responsivity"] for r in rec["images"]}
    assert resp["s1-straight-near-hazcam-L"] < resp["s1-straight-near-navcam-L"]


def test_drive_legs_and_pose_sigmas(run_errors, run_exact):
    # straight run: every leg is its chord; the arc run's last leg (far -> near) is an arc
    for sim, arcs in ((run_errors, set()), (run_exact, {"near"})):
        by_stop = {p.stop: p.T_site_rover_true for p in sim.products}
        labels = [s.label for s in sim.plan.stops]
        for a, b in zip(labels, labels[1:]):
            chord = np.linalg.norm(by_stop[b].t[:2] - by_stop[a].t[:2])
            L = next(s["path_length_m"] for s in sim.record["stops"] if s["label"] == b)
            assert L == pytest.approx(chord * (1.05 if b in arcs else 1.0), rel=1e-12)
    # the odometry poses carry growing 1-sigma claims; exact poses carry none
    sig = [im.pose.sigma_position_m for im in run_errors.downlink.images]
    assert all(s is not None and s > 0 for s in sig) and sig[-1] > sig[0]
    assert all(im.pose.source == "wheel_odometry" for im in run_errors.downlink.images)
    assert all(im.pose.sigma_position_m is None for im in run_exact.downlink.images)
