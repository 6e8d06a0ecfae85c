"""Pre-uplink prediction: mesh, rendering, ground and rocks, planning, Monte Carlo, chain and risks, on exact truth."""

import math

import numpy as np
import pytest

from scipctl.core.camera import cahv_from_intrinsics
from scipctl.core.kinematics import RoverPose
from scipctl.core.transforms import RigidTransform, euler_zyx_to_matrix
from scipctl.pipeline import predict as P
from tests.pipeline import scene as S

# ----------------------------------------------------------------------------- helpers


def heightfield_source(h_fn, x=(-2.0, 14.0), y=(-4.0, 4.0), step=0.02, name="hf"):
    """A TerrainSource whose grid is the height field ``z = -h(x, y)`` (site frame) seen from 20 m above."""
    xs = np.arange(x[0], x[1] + 1e-9, step)
    ys = np.arange(y[0], y[1] + 1e-9, step)
    X, Y = np.meshgrid(xs, ys)
    Z = -h_fn(X, Y)
    xyz = np.stack([X, Y, Z], -1)
    C = np.array([0.5 * (x[0] + x[1]), 0.5 * (y[0] + y[1]), -20.0])
    img = np.full((8, 8), 0.5, np.float32)
    model = cahv_from_intrinsics(4.0, 4.0, 3.5, 3.5, RigidTransform(np.eye(3), C))
    return P.TerrainSource(name, "navcam", xyz, img, model, C, 0)


def flat(X, Y):
    return np.zeros_like(X)


def box_fn(boxes):
    def h(X, Y):
        out = np.zeros_like(X)
        for (x0, y0, x1, y1, hh) in boxes:
            out = np.where((X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1), np.maximum(out, hh), out)
        return out
    return h


def start_pose(x=0.0, y=0.0, yaw=0.0):
    return RoverPose(RigidTransform(euler_zyx_to_matrix(yaw, 0.0, 0.0), np.array([x, y, 0.0])), "test", 0.03, 0.005)


# ----------------------------------------------------------------------------- mesh and rendering


def _pinhole_grid(h, w, ranges):
    m = cahv_from_intrinsics(100.0, 100.0, (w - 1) / 2, (h - 1) / 2, RigidTransform.identity())
    us, vs = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    o, d = m.unproject(np.stack([us, vs], -1).reshape(-1, 2))
    return (o + ranges.reshape(-1, 1) * d).reshape(h, w, 3)


def test_grid_mesh_keeps_a_surface_and_drops_a_depth_step():
    h, w = 12, 16
    smooth = _pinhole_grid(h, w, np.full((h, w), 5.0))
    v, t, used = P.grid_mesh(smooth, np.zeros(3))
    assert len(t) == 2 * (h - 1) * (w - 1) and len(v) == h * w
    step = np.full((h, w), 5.0)
    step[:, w // 2:] = 8.0  # a depth discontinuity between columns w/2 - 1 and w/2
    _, t2, _ = P.grid_mesh(_pinhole_grid(h, w, step), np.zeros(3))
    assert len(t2) == 2 * (h - 1) * (w - 1) - 2 * (h - 1)
    holes = _pinhole_grid(h, w, np.full((h, w), 5.0))
    holes[3, 4] = np.nan  # one invalid vertex removes the 6 triangles that use it
    _, t3, _ = P.grid_mesh(holes, np.zeros(3))
    assert len(t3) == 2 * (h - 1) * (w - 1) - 6


def test_smooth_grid_reduces_range_noise_and_keeps_steps():
    rng = np.random.default_rng(1)
    h, w = 40, 40
    r = np.full((h, w), 5.0)
    r[:, 20:] = 8.0
    noisy = r + rng.normal(0, 0.02, r.shape)
    g = _pinhole_grid(h, w, noisy)
    sm = P.smooth_grid(g, np.zeros(3), sigma_px=1.5, max_rel=0.03)
    rs = np.linalg.norm(sm, axis=2)
    inner = np.s_[5:-5, 5:15]
    assert np.std(rs[inner] - 5.0) < 0.5 * np.std(noisy[inner] - 5.0)
    assert np.all(np.abs(rs - r) < 0.1)  # no point is pulled across the 3 m step
    # points only move along their own rays
    d0 = g / np.linalg.norm(g, axis=2, keepdims=True)
    d1 = sm / np.linalg.norm(sm, axis=2, keepdims=True)
    assert np.max(np.abs(d0 - d1)) < 1e-12


def test_render_through_the_source_camera_gives_the_source_image_back():
    world, dl = S.cached("rock")
    src = [s for s in S.oracle_sources(world, dl, cameras=("pancam",), step=1)]
    ter = P.Terrain(src, smooth_sigma_px=0)
    s = ter.sources[0]
    view = ter.render(s.left_model_site, S.SIZE, S.SIZE)
    ok = np.isfinite(view.image)
    assert ok.mean() > 0.8
    assert np.max(np.abs(view.image[ok] - s.left_img[ok])) < 1e-3
    # and depth equals the distance to the true surface along each ray
    us, vs = np.meshgrid(np.arange(S.SIZE, dtype=float), np.arange(S.SIZE, dtype=float))
    o, d = s.left_model_site.unproject(np.stack([us, vs], -1).reshape(-1, 2))
    t = world.cast(o, d).reshape(S.SIZE, S.SIZE)
    good = ok & np.isfinite(t) & (t < 30)
    assert np.median(np.abs(view.depth_m[good] - t[good])) < 0.01


def test_cast_hits_a_plane_at_the_exact_distance(flat_terrain):
    o = np.array([[1.0, 0.5, -2.0], [3.0, -1.0, -1.5], [7.2, 2.2, -0.3]])
    d = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8]])
    hits = flat_terrain.cast(o, d)
    assert hits.hit.all()
    assert np.allclose(hits.t_m, -o[:, 2] / d[:, 2], atol=1e-4)
    assert np.allclose(hits.points[:, 2], 0.0, atol=1e-4)
    assert np.allclose(np.abs(hits.normals[:, 2]), 1.0, atol=1e-6)
    miss = flat_terrain.cast(np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, -1.0]]))
    assert not miss.hit[0] and not np.isfinite(miss.t_m[0])


# ----------------------------------------------------------------------------- ground and rocks


def test_rock_cells_find_the_tall_box_and_not_the_low_one():
    tall = (2.0, 0.0, 2.5, 0.5, 0.30)
    low = (4.0, 1.0, 4.3, 1.3, 0.08)
    ter = P.Terrain([heightfield_source(box_fn([tall, low]))], smooth_sigma_px=0)
    cells = ter.rock_cells(cell_m=0.05, ground_window_m=1.0, min_height_m=0.15)
    assert len(cells) > 0
    x0, y0, x1, y1, _ = tall
    inside = (cells[:, 0] > x0 - 0.06) & (cells[:, 0] < x1 + 0.06) & (cells[:, 1] > y0 - 0.06) & (cells[:, 1] < y1 + 0.06)
    assert inside.all()
    # the whole top is found (all cells whose centre is inside the box)
    assert len(cells) >= int(round((x1 - x0) / 0.05)) * int(round((y1 - y0) / 0.05))
    assert not np.any((cells[:, 0] > 3.9) & (cells[:, 0] < 4.4) & (cells[:, 1] > 0.9) & (cells[:, 1] < 1.4))


def test_ground_plane_and_pose_on_plane_recover_a_tilted_slope():
    a, b, c = 0.1, -0.05, 0.2
    ter = P.Terrain([heightfield_source(lambda X, Y: -(a * X + b * Y + c))], smooth_sigma_px=0)
    guess = P.pose_on_plane([5.0, 0.5], 0.3, (0.0, 0.0, 0.0))
    body = P.RoverBody()
    plane, n, frac = ter.ground_plane(guess, body)
    assert plane is not None and frac > 0.9
    assert np.allclose(plane, (a, b, c), atol=1e-6)
    T = P.pose_on_plane([5.0, 0.5], 0.3, plane)
    normal_down = np.array([-a, -b, 1.0]) / np.linalg.norm([-a, -b, 1.0])
    assert np.allclose(T.R[:, 2], normal_down, atol=1e-9)
    assert abs(T.t[2] - (a * 5.0 + b * 0.5 + c)) < 1e-9
    assert abs(math.atan2(T.R[1, 0], T.R[0, 0]) - 0.3) < 0.01  # heading kept
    assert abs(P.tilt_of(T) - math.acos(normal_down[2])) < 1e-12
    assert np.allclose(T.R.T @ T.R, np.eye(3), atol=1e-12) and np.linalg.det(T.R) > 0


def test_arm_workspace_and_footprint_distance():
    arm = P.ArmWorkspace(0.6, 1.0, 0.4)
    pts = np.array([[0.8, 0.0], [0.59, 0.0], [1.01, 0.0], [0.8, 0.39], [0.8, 0.41], [-0.8, 0.0]])
    assert arm.contains(pts).tolist() == [True, False, False, True, False, False]
    body = P.RoverBody(0.5, -0.5, 0.4)
    d = body.distance(np.array([[0.0, 0.0], [0.8, 0.0], [0.5, 0.7], [-0.8, -0.8]]))
    assert np.allclose(d, [0.0, 0.3, 0.3, math.hypot(0.3, 0.4)])


# ----------------------------------------------------------------------------- planning


def test_stop_distances_follow_the_paper_schedule():
    p = P.ApproachParams()
    stops = P.stop_distances(10.0, p)
    d = [s[0] for s in stops]
    kinds = dict((round(x, 6), k) for x, k in stops)
    assert all(a > b for a, b in zip(d, d[1:]))
    assert kinds[p.pancam_handoff_m] == "pancam-navcam-handoff"
    assert kinds[p.hazcam_handoff_m] == "navcam-hazcam-handoff"
    assert kinds[1.4] == "hazcam" and stops[-1] == (p.final_distance_m, "final")
    prev = 10.0
    for x, k in stops:
        step = max(p.stop_fraction * prev, p.min_leg_m)
        if k in ("pancam", "navcam"):  # regular stops: stop_fraction of the remaining distance from the last stop
            assert prev - x == pytest.approx(step, abs=1e-9)
            assert k == ("pancam" if x > p.pancam_handoff_m else "navcam")
        elif prev > p.hazcam_handoff_m:  # a special stop replaces a regular one that would come too close to it
            assert prev - x <= step + p.merge_m + 1e-9
        prev = x
    near = P.stop_distances(3.0, p)  # starting inside the pancam range: the first stop hands off
    assert near[0][1] == "pancam-navcam-handoff" and all(k != "pancam" for _, k in near)
    assert P.stop_distances(0.7, p) == []


def test_straight_plan_on_flat_ground(rc, flat_terrain):
    T = np.array([9.0, 1.0, 0.0])
    plan = P.plan_approach(start_pose(), T, flat_terrain, rc)
    assert plan.detour_rad == 0.0 and not plan.clearance["blocked"]
    u = T[:2] / np.linalg.norm(T[:2])
    for st in plan.stops[1:]:
        xy = st.T_site_rover.t[:2]
        assert abs(u[0] * xy[1] - u[1] * xy[0]) < 1e-9  # on the line start -> target
        assert st.distance_m == pytest.approx(np.linalg.norm(T[:2] - xy), abs=1e-9)
        assert abs(st.T_site_rover.t[2]) < 1e-6 and st.tilt_rad < 1e-6
        for sh in st.cameras:
            assert sh.in_fov and sh.uv is not None
            if sh.pan_rad is not None:  # mast cameras centred on the target
                spec = rc.spec(sh.camera, "left")
                assert np.allclose(sh.uv, [(spec.width - 1) / 2, (spec.height - 1) / 2], atol=1e-3)
    fin = plan.final
    assert fin.kind == "final" and fin.distance_m == pytest.approx(plan.params.final_distance_m, abs=1e-9)
    assert plan.path_length_m == pytest.approx(np.linalg.norm(T[:2]) - plan.params.final_distance_m, abs=1e-9)
    xy_r = fin.T_site_rover.inverse().apply(T)[:2]
    assert np.allclose(xy_r, [plan.params.final_distance_m, 0.0], atol=1e-9)


def test_plan_detours_around_a_rock_and_reports_a_blocked_approach(rc):
    T = np.array([9.0, 0.0, 0.0])
    rock = (4.5, -0.4, 5.2, 0.4, 0.4)  # on the direct line
    ter = P.Terrain([heightfield_source(box_fn([rock]))], smooth_sigma_px=0)
    plan = P.plan_approach(start_pose(), T, ter, rc)
    assert plan.detour_rad != 0.0
    assert plan.clearance["min_rock_m"] >= plan.params.rock_keep_out_m and not plan.clearance["blocked"]
    wall = (6.0, -4.0, 6.3, 4.0, 0.5)  # a wall across every approach
    ter2 = P.Terrain([heightfield_source(box_fn([wall]))], smooth_sigma_px=0)
    plan2 = P.plan_approach(start_pose(), T, ter2, rc)
    assert plan2.clearance["blocked"] and plan2.clearance["min_rock_m"] < plan2.params.rock_keep_out_m


# ----------------------------------------------------------------------------- Monte Carlo


def test_pose_errors_are_a_random_walk_with_the_stated_variance(rc):
    plan = P.plan_approach(start_pose(), np.array([9.0, 0.0, 0.0]), None, rc)
    up = P.UncertaintyParams(drive_error_frac=0.02, yaw_error_rad_per_m=0.0)
    errs = P.sample_pose_errors(plan, up, 0.03, 0.0, np.random.default_rng(0), 40000)
    var = 0.0
    for st in plan.stops[1:]:
        var += 0.03 ** 2 + (0.02 * st.leg_m) ** 2
        dxy, dyaw = errs[st.index]
        assert np.var(dxy[:, 0]) == pytest.approx(var, rel=0.05)
        assert np.var(dxy[:, 1]) == pytest.approx(var, rel=0.05)
        assert np.all(dyaw == 0.0)


def test_monte_carlo_without_error_keeps_everything_in_view(rc, flat_terrain):
    T = np.array([9.0, 0.5, 0.0])
    plan = P.plan_approach(start_pose(), T, flat_terrain, rc)
    up = P.UncertaintyParams(n_samples=200, drive_error_frac=0.0, yaw_error_rad_per_m=0.0, disparity_sigma_px=0.0)
    mc = P.monte_carlo(plan, flat_terrain, rc, T, up, 0.0, 0.0)
    for v in mc.views:
        assert v.p_ok == 1.0 and v.offset_px_rms < 1e-6
    assert mc.p_arm_workspace == 1.0 and mc.p_success_geometry == 1.0


def test_monte_carlo_probability_falls_with_the_pose_error(rc, flat_terrain):
    T = np.array([9.0, 0.5, 0.0])
    plan = P.plan_approach(start_pose(), T, flat_terrain, rc)
    up = P.UncertaintyParams(n_samples=400)
    small = P.monte_carlo(plan, flat_terrain, rc, T, up, 0.02, 0.003)
    big = P.monte_carlo(plan, flat_terrain, rc, T, up, 0.5, 0.15)
    p_small = min(v.p_in_search for v in small.views)
    p_big = min(v.p_in_search for v in big.views)
    assert p_big < p_small and p_big < 0.9
    assert big.p_success_geometry < small.p_success_geometry
    assert max(v.offset_px_rms for v in big.views) > 3 * max(v.offset_px_rms for v in small.views)


def test_occlusion_by_a_wall_is_seen_in_the_views_the_monte_carlo_and_the_risks(rc):
    T = np.array([9.0, 0.0, 0.0])
    wall = (8.4, -1.0, 8.6, 1.0, 2.5)  # 2.5 m high, in front of the target
    ter = P.Terrain([heightfield_source(box_fn([wall]))], smooth_sigma_px=0)
    assert ter.occluded(np.array([[5.0, 0.0, -1.5]]), T[None])[0]
    assert not ter.occluded(np.array([[9.5, 0.0, -1.5]]), T[None])[0]
    plan = P.plan_approach(start_pose(), T, None, rc)  # plan without the terrain (no detour)
    mc = P.monte_carlo(plan, ter, rc, T, P.UncertaintyParams(n_samples=50), 0.02, 0.003)
    far = [v for v in mc.views if plan.stops[v.stop].distance_m > 1.5]
    assert far and all(v.p_visible == 0.0 for v in far)
    risks = P.assess_risks(plan, mc, None, P.PredictParams())
    assert any("occlusion" in " ".join(r.reasons) for r in risks)


# ----------------------------------------------------------------------------- chain on rendered views


@pytest.fixture(scope="module")
def slab_case():
    world, dl = S.cached("slab")
    ter = P.Terrain(S.oracle_sources(world, dl, step=2))
    return world, dl, ter


def test_chain_on_exact_terrain_keeps_the_slab_target(slab_case):
    world, dl, ter = slab_case
    rec = S.designation_record(dl, "t_slab")
    params = P.PredictParams(uncertainty=P.UncertaintyParams(n_track_samples=2, n_samples=300))
    pred = P.predict_target(dl, rec, params, terrain=ter)
    nominal = [s for s in pred.chain.samples if s.sample < 0][0]
    assert nominal.ok
    for st in nominal.steps:
        assert st["kept"] and st["error_m"] is not None and st["error_m"] < P.LOST_M
    # the surface point is the true target (exact terrain)
    assert np.linalg.norm(pred.surface_point_site - S.TARGET_SLAB_SITE) < 0.01
    assert pred.accuracy["nominal_final_error_m"] < 0.02
    # confidence = P(geometry ok) x fraction of the geometrically ok rendered chains that kept the target
    runs = [c for c in pred.chain.samples if c.sample >= 0 and pred.mc.samples_ok[c.sample]] or \
        [c for c in pred.chain.samples if c.sample < 0]
    assert pred.confidence == pytest.approx(pred.mc.p_success_geometry * np.mean([c.ok for c in runs]))
    # without pose error every sample is the nominal approach: certain success on exact terrain
    exact = P.UncertaintyParams(sigma_position_m=0.0, sigma_yaw_rad=0.0, drive_error_frac=0.0, yaw_error_rad_per_m=0.0,
                                disparity_sigma_px=0.0, n_samples=100, n_track_samples=1)
    p0 = P.predict_target(dl, dict(rec, range_sigma_m=0.0), P.PredictParams(uncertainty=exact), terrain=ter)
    assert p0.mc.p_success_geometry == 1.0 and p0.confidence == 1.0
    assert all(reason.startswith("drift") for r in p0.risks for reason in r.reasons)  # accuracy notes only
    kinds = [s["kind"] for s in nominal.steps]
    assert "handoff pancam->navcam" in kinds and "handoff navcam->hazcam" in kinds
    assert set(pred.views) == {(st.index, sh.camera) for st in pred.plan.stops[1:] for sh in st.cameras}


def test_low_texture_target_is_flagged():
    patch = ((8.6, -0.9), (9.9, 0.9))
    world = S.World(flat_patch=patch)
    target = np.array([9.3, 0.0, 0.0])
    dl = S.make_downlink(world, targets={"t_sand": target})
    ter = P.Terrain(S.oracle_sources(world, dl, step=2))
    params = P.PredictParams(run_chain=False, uncertainty=P.UncertaintyParams(n_samples=50))
    pred = P.predict_target(dl, S.designation_record(dl, "t_sand"), params, terrain=ter)
    reasons = " ".join(" ".join(r.reasons) for r in pred.risks)
    assert "low texture" in reasons


def test_resolve_target_prefers_targets_json_and_rejects_unknown_ids(slab_case):
    from scipctl.model import InputError

    _, dl, _ = slab_case
    rec = {"id": "t_slab", "ok": True, "product_id": "pancam_left_1_0", "pixel_uv": [1.0, 2.0], "xyz_site_m": [1, 2, 3]}
    got, now = P.resolve_target(dl, "t_slab", {"targets": [rec]})
    assert got is rec and not now
    with pytest.raises(InputError) as e:
        P.resolve_target(dl, "nope", {"targets": [rec]})
    assert "nope" in str(e.value) and "t_slab" in str(e.value)
