"""Scenario geometry and the exactness of marks and truth."""

import numpy as np
import pytest

from scipctl.sim.errors import ErrorSettings
from scipctl.sim.scenarios import KINDS, build_run, list_runs, plan_run, project_visible, scene_for

from .conftest import SMALL


def _truth_projection(dl, product_id, xyz_site):
    tr = dl.truth_for(product_id)
    X_rover = tr.pose.T_site_rover.inverse().apply(np.asarray(xyz_site, float)[None])
    return tr.camera_model.project(X_rover)[0]


@pytest.mark.parametrize("which", ["run_errors", "run_exact"])
def test_marks_are_the_projection_through_the_true_model(which, request):
    sim = request.getfixturevalue(which)
    dl = sim.downlink
    assert len(dl.targets) == 3
    n = 0
    for tm in dl.targets:
        X = dl.truth_target(tm.id).xyz_site_m
        assert tm.marks, f"{tm.id} is marked nowhere"
        for m in tm.marks:
            uv = _truth_projection(dl, m.product_id, X)
            assert np.hypot(uv[0] - m.u, uv[1] - m.v) < 1e-6
            assert m.sigma_px == 0.0
            n += 1
    assert n >= 9


@pytest.mark.parametrize("which", ["run_errors", "run_exact", "run_full_exact"])
def test_ray_through_a_mark_hits_the_target(which, request):
    sim = request.getfixturevalue(which)
    dl = sim.downlink
    worst = 0.0
    for tm in dl.targets:
        X = dl.truth_target(tm.id).xyz_site_m
        for m in tm.marks:
            tr = dl.truth_for(m.product_id)
            model_site = tr.camera_model.transformed(tr.pose.T_site_rover)
            o, d = model_site.unproject(np.array([[m.u, m.v]]))
            hit = sim.scene.cast(o, d)
            assert hit.hit[0]
            worst = max(worst, float(np.linalg.norm(hit.points[0] - X)))
    assert worst < 1e-3, f"ray through a mark misses its target by {worst * 1e3:.3f} mm"


def test_targets_visible_in_every_key_image(run_errors):
    dl = run_errors.downlink
    for tm in dl.targets:
        marked = {m.product_id for m in tm.marks}
        for stop, cam in run_errors.plan.key_images:
            for eye in "LR":
                assert f"s1-straight-{stop}-{cam}-{eye}" in marked, (tm.id, stop, cam, eye)


def test_occluded_and_off_image_points_are_not_marked(run_exact):
    sim = run_exact
    p = next(q for q in sim.products if q.stop == "near" and q.camera == "hazcam" and q.eye == "left")
    m = p.model_true_site
    aim = sim.scene.target_rock.aim_point_site()
    uv = m.project(aim[None])
    o, d = m.unproject(uv)
    h = sim.scene.cast(o, d)
    front = h.points[0]
    behind = front + 0.3 * d[0]  # inside / behind the rock, same pixel
    far_left = front + 50.0 * np.cross(d[0], [0, 0, 1.0])  # way off to the side: outside the image
    uvs, vis = project_visible(sim.scene, m, p.width, p.height, np.array([front, behind, far_left]))
    assert vis.tolist() == [True, False, False]
    assert np.allclose(uvs[0], uvs[1], atol=1e-6)  # same pixel, only occlusion tells them apart


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


def test_paper_distances_and_arc_angle(run_full_exact, run_exact):
    def cam_ground_point(sim, stop, cam):
        ps = [p for p in sim.products if p.stop == stop and p.camera == cam]
        c = np.mean([p.model_true_site.C for p in ps], axis=0)
        return c[:2]

    rock_xy = run_full_exact.scene.target_rock.centre_xy_m
    for sim in (run_full_exact, run_exact):
        d_haz = np.linalg.norm(cam_ground_point(sim, "near", "hazcam") - rock_xy)
        d_far = np.linalg.norm(cam_ground_point(sim, "far", "navcam") - rock_xy)
        d_mid = np.linalg.norm(cam_ground_point(sim, "mid", "navcam") - rock_xy)
        d_p10 = np.linalg.norm(cam_ground_point(sim, "pan10", "pancam") - rock_xy)
        assert abs(d_haz - 1.0) < 0.05 and abs(d_far - 3.0) < 0.05
        assert abs(d_mid - 4.5) < 0.1 and abs(d_p10 - 10.0) < 0.1
        # the rover faces the rock at the near stop
        near = next(p for p in sim.products if p.stop == "near")
        fwd = near.T_true.R[:2, 0]
        to_rock = rock_xy - near.T_true.t[:2]
        ang = np.degrees(np.arccos(fwd @ to_rock / np.linalg.norm(fwd) / np.linalg.norm(to_rock)))
        assert ang < 3.0

    def bearing(sim, stop, cam):
        v = cam_ground_point(sim, stop, cam) - rock_xy
        return np.arctan2(v[1], v[0])

    straight = np.degrees(bearing(run_full_exact, "far", "navcam") - bearing(run_full_exact, "near", "hazcam"))
    arc = np.degrees(bearing(run_exact, "far", "navcam") - bearing(run_exact, "near", "hazcam"))
    assert abs((straight + 180) % 360 - 180) < 2.0
    assert abs(abs((arc + 180) % 360 - 180) - 30.0) < 2.0


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


def test_washed_out_far_navcam_in_run_s2_arc():
    sim = build_run("paper", "s2-arc", 1, image_scale=SMALL, supersample=1)
    stats = {}
    for im in sim.downlink.images:
        px = im.pixels
        stats[im.product_id] = np.mean(px == np.iinfo(px.dtype).max)
    far = [v for k, v in stats.items() if "-far-navcam-" in k]
    near = [v for k, v in stats.items() if "-near-navcam-" in k]
    assert min(far) > 0.3, f"far navcam should be washed out (saturated fraction {far})"
    assert max(near) < 0.05
    washed = [r["product_id"] for r in sim.record["images"] if r["washed_out"]]
    assert sorted(washed) == ["s2-arc-far-navcam-L", "s2-arc-far-navcam-R"]


def test_paper_has_18_cases_of_all_kinds():
    kinds = []
    for run in list_runs("paper"):
        sim = build_run("paper", run, 1, image_scale=SMALL, supersample=1, render=False)
        assert len(sim.downlink.targets) == 3
        assert len({t.kind for t in sim.downlink.targets}) == 3
        assert len({t.id for t in sim.downlink.targets}) == 3
        kinds += [t.kind for t in sim.downlink.targets]
        pos = sim.downlink.positions()
        assert len(pos) == len(set(pos)) == 4
    assert len(kinds) == 18
    assert set(kinds) == set(KINDS)


def test_build_is_deterministic(run_exact):
    again = build_run("paper", "s1-arc", 1, errors=ErrorSettings.none(), image_scale=SMALL, supersample=1)
    a, b = run_exact.downlink, again.downlink
    assert [i.png for i in a.images] == [i.png for i in b.images]
    for t1, t2 in zip(a.targets, b.targets):
        assert [(m.product_id, m.u, m.v) for m in t1.marks] == [(m.product_id, m.u, m.v) for m in t2.marks]
    other = plan_run("paper", "s1-arc", 2)  # another seed, another scene and approach
    assert other.scene_seed != run_exact.plan.scene_seed and other.bearing_rad != run_exact.plan.bearing_rad


def test_traverse_plan_and_marks():
    for run in list_runs("traverse"):
        plan = plan_run("traverse", run, 1)
        d = [np.linalg.norm(s.xy_m) for s in plan.stops]
        assert all(b < a for a, b in zip(d, d[1:]))
        cams = [s.cameras for s in plan.stops]
        assert cams[0] == ("pancam",) and "hazcam" in cams[-1]
        assert any("pancam" in c and "navcam" in c for c in cams), "a pancam->navcam handoff stop"
        first_haz = next(i for i, c in enumerate(cams) if "hazcam" in c)
        assert all("hazcam" in c for c in cams[first_haz:])
        # steps are 10-20 % of the remaining distance except where a stop is forced (handoffs, the end)
        mast_d = [np.linalg.norm(s.xy_m + 0.37 * np.array([np.cos(s.yaw_rad), np.sin(s.yaw_rad)])) for s in plan.stops]
        frac = [1 - b / a for a, b in zip(mast_d, mast_d[1:])]
        assert sum(0.099 < f < 0.201 for f in frac) >= len(frac) - 4
    sim = build_run("traverse", "s1-curved", 1, image_scale=SMALL, supersample=1, render=False)
    dl = sim.downlink
    assert len(dl.targets) == 3
    for tm in dl.targets:
        X = dl.truth_target(tm.id).xyz_site_m
        assert len(tm.marks) >= 8
        for m in tm.marks:
            assert np.hypot(*(_truth_projection(dl, m.product_id, X) - [m.u, m.v])) < 1e-6


def test_scene_is_shared_by_the_runs_of_a_scene():
    a = scene_for(plan_run("paper", "s3-straight", 1))
    b = scene_for(plan_run("paper", "s3-arc", 1))
    assert a is b
    # the rover's corridors are free of rocks
    for plan in (plan_run("paper", "s3-straight", 1), plan_run("paper", "s3-arc", 1)):
        for s in plan.stops:
            for r in a.rocks[1:]:
                assert np.linalg.norm(r.centre_xy_m - s.xy_m) > r.radius_m + 0.6


def test_drive_legs_and_pose_sigmas(run_errors, run_exact):
    # straight run: every leg is its chord; the arc run's last leg (far -> near) is an arc
    for sim, arcs in ((run_errors, set()), (run_exact, {"near"})):
        by_stop = {p.stop: p.T_true for p in sim.products}
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
