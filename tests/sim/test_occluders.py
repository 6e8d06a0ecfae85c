"""Shallow occluders (scipctl/sim/occluders.py), checked by independent ray casts from the true models in the scene
with its pebbles: each hidden point is behind its pebble from the hazcam over the whole 4 px disk, the navcams see
it, and the run's own targets are seen by every image exactly as before."""

from dataclasses import replace

import numpy as np
import pytest

from scipctl.sim.build import build_run
from scipctl.sim.errors import ErrorSettings
from scipctl.sim.extra_targets import HIDDEN_DISK_PX, OCCLUDED_KIND, extra_marks
from scipctl.sim.marks import project_visible
from scipctl.sim.occluders import PEBBLE_HEIGHT_M, PEBBLE_LENGTH_M, add_shallow_occluders

MIN_DEPTH_M = 0.03


def _ids(sim):
    pid = {(p.stop, p.camera, p.eye): p.product_id for p in sim.products}
    return pid[("near", "hazcam", "left")], [pid[("near", "navcam", "left")], pid[("near", "navcam", "right")]]


def _visibility(sim, X):
    return {p.product_id: project_visible(sim.scene, p.model_true_site, p.width, p.height, X)[1] for p in sim.products}


@pytest.fixture(scope="module")
def placed():
    """paper s1-straight, seed 1, no errors, geometry only; the run's targets' visibility before any pebble."""
    sim = build_run("paper", "s1-straight", 1, errors=ErrorSettings.none(), render=False)
    haz, nav = _ids(sim)
    protect = np.array([t.xyz_site_m for t in sim.downlink.truth_targets])
    before = _visibility(sim, protect)
    scene0 = sim.scene
    n_rocks = len(scene0.rocks)
    scene, got = add_shallow_occluders(scene0, sim.products, haz, nav, protect, 4, np.random.default_rng(5),
                                       min_depth_m=MIN_DEPTH_M)
    assert len(scene0.rocks) == n_rocks, "the given scene (shared by build_run's cache) must not change"
    return replace(sim, scene=scene), protect, before, n_rocks, got


def test_pebbles_are_added_to_the_scene(placed):
    sim, _, _, n_rocks, got = placed
    assert len(got) == 4, "seed 1's scene has room for four pebbles in 400 tries"
    assert [s.target.id for s in got] == ["p01", "p02", "p03", "p04"]
    assert all(s.target.kind == OCCLUDED_KIND for s in got)
    assert sim.scene.rocks[n_rocks:] == [s.rock for s in got]
    for s in got:
        # pebble-sized: the drawn extents, changed only by the yaw, lean and roughness make_rock applies (the
        # footprint of a yawed box is at most sqrt(2) x its length; 20 % on the height for the lean and noise)
        assert max(s.rock.size_m[:2]) <= np.sqrt(2) * PEBBLE_LENGTH_M[1]
        assert s.rock.size_m[2] <= 1.2 * PEBBLE_HEIGHT_M[1]
        assert MIN_DEPTH_M <= s.depth_m < 0.3


def test_hidden_points_are_behind_their_pebble_and_seen_by_the_navcams(placed):
    sim, _, _, _, got = placed
    haz, nav = _ids(sim)
    by = {p.product_id: p for p in sim.products}
    h = by[haz]
    X = np.array([s.target.xyz_site_m for s in got])
    uv, vis = project_visible(sim.scene, h.model_true_site, h.width, h.height, X)
    assert not vis.any()
    # the point projects to the pixel its ray was cast through (float64 rounding only)
    assert np.abs(uv - np.array([s.hazcam_uv for s in got])).max() < 1e-6
    ang = np.arange(16) * np.pi / 8
    for r_px in (0.0, 1.0, 2.0, 3.0, HIDDEN_DISK_PX):
        for j, s in enumerate(got):
            ring = uv[j] + r_px * np.stack([np.cos(ang), np.sin(ang)], 1)
            o_r, d_r = h.model_true_site.unproject(ring)
            hits = sim.scene.cast(o_r, d_r)
            dist = np.linalg.norm(X[j] - o_r, axis=1)
            # 1 cm of margin between the 8 + 1 checked rays and these 16, as in test_extra_targets
            assert (hits.t_m <= dist - (MIN_DEPTH_M - 0.01)).all(), (j, r_px)
            if r_px == 0.0:  # the first hit is on the pebble: within its bounding box (1 mm slack, float32 casts)
                P = hits.points
                lo, hi = s.rock.vertices.min(0) - 1e-3, s.rock.vertices.max(0) + 1e-3
                assert np.all((P >= lo) & (P <= hi)), j
    for pid in nav:
        p = by[pid]
        _, vis = project_visible(sim.scene, p.model_true_site, p.width, p.height, X)
        assert vis.all(), pid
    for tm in extra_marks(sim.scene, sim.products, [s.target for s in got]):
        got_ids = {m.product_id for m in tm.marks}
        assert haz not in got_ids and set(nav) <= got_ids


def test_the_runs_targets_are_seen_as_before(placed):
    sim, protect, before, _, _ = placed
    after = _visibility(sim, protect)
    assert before.keys() == after.keys()
    for pid in before:
        assert np.array_equal(before[pid], after[pid]), pid


def test_the_same_pebbles_twice(placed):
    sim0, _, _, _, got0 = placed
    sim = build_run("paper", "s1-straight", 1, errors=ErrorSettings.none(), render=False)
    haz, nav = _ids(sim)
    protect = np.array([t.xyz_site_m for t in sim.downlink.truth_targets])
    _, got = add_shallow_occluders(sim.scene, sim.products, haz, nav, protect, 4, np.random.default_rng(5),
                                   min_depth_m=MIN_DEPTH_M)
    assert [s.target.id for s in got] == [s.target.id for s in got0]
    for a, b in zip(got, got0):
        assert np.array_equal(a.target.xyz_site_m, b.target.xyz_site_m)
        assert np.array_equal(a.rock.vertices, b.rock.vertices)
        assert a.depth_m == b.depth_m


def test_later_pebbles_keep_earlier_hidden_points_in_the_navcams_view():
    """A later pebble must not hide an earlier pebble's point from the navcams. The draw of
    ``trust_render.py filtered-specks 3132 s2-arc --shallow 6`` met that case: before the check, its fifth pebble hid
    ``p01`` from both near navcams (so ``p01`` had no navcam mark and no evidence row in the session-23 table)."""
    from scipctl.sim.families import family_of_run
    from scipctl.sim.scenarios import _rng, default_errors

    fam = family_of_run("filtered-specks", "paper", "s2-arc", 3132)
    sim = build_run("paper", "s2-arc", 3132, errors=default_errors("paper").scaled(fam.error_scale), render=False,
                    family=fam)
    haz, nav = _ids(sim)
    protect = np.array([t.xyz_site_m for t in sim.downlink.truth_targets])
    scene, got = add_shallow_occluders(sim.scene, sim.products, haz, nav, protect, 6,
                                       _rng(3132, "paper", "s2-arc", "shallow-occluders"))
    assert len(got) == 6
    X = np.array([s.target.xyz_site_m for s in got])
    by = {p.product_id: p for p in sim.products}
    for pid in nav:
        p = by[pid]
        _, vis = project_visible(scene, p.model_true_site, p.width, p.height, X)
        assert vis.all(), (pid, [s.target.id for s, v in zip(got, vis) if not v])
