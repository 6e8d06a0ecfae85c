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
