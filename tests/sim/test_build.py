"""Building runs: washed-out pairs, determinism, the shared scene cache (scipctl/sim/build.py)."""

import numpy as np

from scipctl.sim.build import build_run, scene_for
from scipctl.sim.errors import ErrorSettings
from scipctl.sim.scenarios import plan_run

from .conftest import SMALL


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


def test_build_is_deterministic(run_exact):
    again = build_run("paper", "s1-arc", 1, errors=ErrorSettings.none(), image_scale=SMALL, supersample=1)
    a, b = run_exact.downlink, again.downlink
    assert [i.png for i in a.images] == [i.png for i in b.images]
    for t1, t2 in zip(a.targets, b.targets):
        assert [(m.product_id, m.u, m.v) for m in t1.marks] == [(m.product_id, m.u, m.v) for m in t2.marks]
    other = plan_run("paper", "s1-arc", 2)  # another seed, another scene and approach
    assert other.scene_seed != run_exact.plan.scene_seed and other.bearing_rad != run_exact.plan.bearing_rad


def test_scene_is_shared_by_the_runs_of_a_scene():
    a = scene_for(plan_run("paper", "s3-straight", 1))
    b = scene_for(plan_run("paper", "s3-arc", 1))
    assert a is b
    # the rover's corridors are free of rocks
    for plan in (plan_run("paper", "s3-straight", 1), plan_run("paper", "s3-arc", 1)):
        for s in plan.stops:
            for r in a.rocks[1:]:
                assert np.linalg.norm(r.centre_xy_m - s.xy_m) > r.radius_m + 0.6


def test_render_stops_renders_as_build_run_does():
    """sim/build.render_stops on a run built without pixels gives, stop by stop, the bytes build_run renders (the
    scripts that re-render some stops, docs/scripts/trust_render.py and sun_change_render.py, rely on it)."""
    from scipctl.sim.build import build_run, render_stops
    from scipctl.sim.scenarios import default_errors

    full = build_run("paper", "s1-straight", 3, image_scale=0.125, supersample=1)
    bare = build_run("paper", "s1-straight", 3, image_scale=0.125, supersample=1, render=False)
    pngs = render_stops(bare, default_errors("paper"), {"near", "far"}, supersample=1)
    want = {im.product_id: im.png for im in full.downlink.images if "-near-" in im.product_id or "-far-" in im.product_id}
    assert sorted(pngs) == sorted(want) and all(pngs[k] == want[k] for k in want)
    assert all(im.png != pngs.get(im.product_id) for im in bare.downlink.images)  # bare's own images untouched


def _same_pose(a, b) -> bool:
    return bool(np.array_equal(a.T_site_rover.R, b.T_site_rover.R) and np.array_equal(a.T_site_rover.t, b.T_site_rover.t))


def test_error_draw_keeps_todays_stop_and_draws_tomorrows_errors_anew(run_errors):
    """``error_draw=N``: the first stop's images and poses and the truth stay the seed's; every later image, the
    odometry and the later stops' pointing and vibration are another draw; the fixed errors are unchanged."""
    drawn = build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, error_draw=1)
    a, b = run_errors.downlink, drawn.downlink
    stop0 = run_errors.plan.stops[0].label
    assert stop0 == "pan10"
    assert [i.product_id for i in a.images] == [i.product_id for i in b.images]
    for ia, ib in zip(a.images, b.images):
        if f"-{stop0}-" in ia.product_id:
            assert ia.png == ib.png and _same_pose(ia.pose, ib.pose)
        else:
            assert ia.png != ib.png
    for ta, tb in zip(a.truth_images, b.truth_images):  # true poses are the plan's; true models differ by pointing
        assert _same_pose(ta.pose, tb.pose)
    assert [t.id for t in a.targets] == [t.id for t in b.targets]
    assert all(np.array_equal(x.xyz_site_m, y.xyz_site_m) for x, y in zip(a.truth_targets, b.truth_targets))
    ra, rb = run_errors.record, drawn.record
    assert "error_draw" not in ra and rb["error_draw"] == 1
    assert ra["errors"] == rb["errors"] and ra["mast_true"] == rb["mast_true"]
    assert ra["stops"][0]["pairs"] == rb["stops"][0]["pairs"]
    assert ra["stops"][0]["estimated_pose"] == rb["stops"][0]["estimated_pose"]
    for sa, sb in zip(ra["stops"][1:], rb["stops"][1:]):
        assert sa["true_pose"] == sb["true_pose"] and sa["estimated_pose"] != sb["estimated_pose"]
        assert [p["pan_rad"] for p in sa["pairs"]] != [p["pan_rad"] for p in sb["pairs"]] or not sa["pairs"][0]["pan_rad"]
    assert ra["odometry"]["run_heading_drift_rad_per_m"] != rb["odometry"]["run_heading_drift_rad_per_m"]
    again = build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, error_draw=1)
    assert [i.png for i in again.downlink.images] == [i.png for i in b.images]  # a draw is as deterministic as a seed
    other = build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, error_draw=2, render=False)
    assert other.record["odometry"] != rb["odometry"]


def test_error_draw_zero_is_the_seeds_own_errors(run_errors):
    same = build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, error_draw=0)
    assert [i.png for i in same.downlink.images] == [i.png for i in run_errors.downlink.images]
    assert same.record == run_errors.record


def test_render_stops_follows_the_error_draw():
    from scipctl.sim.build import render_stops
    from scipctl.sim.scenarios import default_errors

    full = build_run("paper", "s1-straight", 3, image_scale=0.125, supersample=1, error_draw=2)
    bare = build_run("paper", "s1-straight", 3, image_scale=0.125, supersample=1, render=False, error_draw=2)
    pngs = render_stops(bare, default_errors("paper"), {"pan10", "near"}, supersample=1)
    want = {im.product_id: im.png for im in full.downlink.images if "-near-" in im.product_id or "-pan10-" in im.product_id}
    assert sorted(pngs) == sorted(want) and all(pngs[k] == want[k] for k in want)


def test_error_draw_must_be_a_whole_number_at_least_zero():
    import pytest

    for bad in (-1, True, 1.5):
        with pytest.raises(ValueError, match="error_draw"):
            build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, render=False, error_draw=bad)
