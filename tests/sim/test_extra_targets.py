"""Extra and occluded targets of the trust-model data (scipctl/sim/extra_targets.py), checked by independent ray
casts from the true models: an extra target is seen by every required image, an occluded one is seen by the
navcams and hidden from the hazcam by a surface at least ``min_depth_m`` in front of it."""

import numpy as np
import pytest

from scipctl.sim.extra_targets import (HIDDEN_DISK_PX, OCCLUDED_KIND, choose_extra_targets, choose_occluded_targets,
                                       extra_marks)
from scipctl.sim.build import build_run
from scipctl.sim.errors import ErrorSettings
from scipctl.sim.marks import project_visible

MIN_DEPTH_M = 0.05


def _ids(sim):
    pid = {(p.stop, p.camera, p.eye): p.product_id for p in sim.products}
    return (pid[("near", "hazcam", "left")], [pid[("near", "hazcam", "right")]],
            [pid[("near", "navcam", "left")], pid[("near", "navcam", "right")]])


@pytest.fixture(scope="module")
def run_seed2():
    """paper s1-straight, seed 2, no errors, geometry only (seed 1's scene has no point hidden over a whole 4 px
    disk from its hazcam and seen by its navcams; seed 2's has four)."""
    return build_run("paper", "s1-straight", 2, errors=ErrorSettings.none(), render=False)


@pytest.fixture(scope="module")
def occluded(run_seed2):
    haz, _, nav = _ids(run_seed2)
    got = choose_occluded_targets(run_seed2.scene, run_seed2.products, haz, nav, 6,
                                  np.random.default_rng(7), min_depth_m=MIN_DEPTH_M)
    assert got, "the paper scene has no point the navcams see behind something the hazcam sees"
    return got


def test_occluded_targets_are_hidden_from_the_hazcam_and_seen_by_the_navcams(run_seed2, occluded):
    sim = run_seed2
    haz, _, nav = _ids(sim)
    by = {p.product_id: p for p in sim.products}
    X = np.array([t.xyz_site_m for t, _, _ in occluded])
    assert all(t.kind == OCCLUDED_KIND for t, _, _ in occluded)
    assert [t.id for t, _, _ in occluded] == [f"o{i + 1:02d}" for i in range(len(occluded))]
    h = by[haz]
    uv, vis = project_visible(sim.scene, h.model_true_site, h.width, h.height, X)
    assert not vis.any()
    # the point projects to the pixel whose ray was followed (the ray's own point: float64 rounding only, measured
    # <= 1.7e-13 px on seeds 2-5)
    assert np.abs(uv - np.array([u for _, _, u in occluded])).max() < 1e-6
    # an independent cast from that pixel's ray origin towards the point stops short of it by the reported depth
    o, _ = h.model_true_site.unproject(uv)
    dist = np.linalg.norm(X - o, axis=1)
    hits = sim.scene.cast(o, (X - o) / dist[:, None])
    gap = dist - hits.t_m
    depth = np.array([d for _, d, _ in occluded])
    assert (gap >= MIN_DEPTH_M - 1e-6).all() and (depth >= MIN_DEPTH_M).all()
    # the same surfaces, cast once or layer by layer (1 mm steps skip none). Open3D casts in float32: t at <= 2.5 m
    # is good to one ulp, 2.4e-7 m, so 1e-6 m is 4 ulp (measured here: <= 2.2e-16, both casts meet the same
    # triangle along nearly the same ray)
    assert np.abs(gap - depth).max() < 1e-6
    # hidden over the whole disk: rays 1, 2, 3 and 4 px away, in 16 directions (not only the rays it checked)
    ang = np.arange(16) * np.pi / 8
    for r_px in (1.0, 2.0, 3.0, HIDDEN_DISK_PX):
        for j in range(len(X)):
            ring = uv[j] + r_px * np.stack([np.cos(ang), np.sin(ang)], 1)
            o_r, d_r = h.model_true_site.unproject(ring)
            t = sim.scene.cast(o_r, d_r).t_m
            # 1 cm of margin: between the checked rays the occluder's edge may come a little nearer the point
            assert (t <= np.linalg.norm(X[j] - o_r, axis=1) - (MIN_DEPTH_M - 0.01)).all(), (j, r_px)
    for pid in nav:
        p = by[pid]
        _, vis = project_visible(sim.scene, p.model_true_site, p.width, p.height, X)
        assert vis.all(), pid
    marks = extra_marks(sim.scene, sim.products, [t for t, _, _ in occluded])
    for tm in marks:
        got = {m.product_id for m in tm.marks}
        assert haz not in got and set(nav) <= got


def test_occluded_targets_are_a_function_of_the_seed(run_seed2, occluded):
    haz, _, nav = _ids(run_seed2)
    again = choose_occluded_targets(run_seed2.scene, run_seed2.products, haz, nav, 6,
                                    np.random.default_rng(7), min_depth_m=MIN_DEPTH_M)
    assert [(t.id, t.xyz_site_m.tolist(), d) for t, d, _ in again] == [(t.id, t.xyz_site_m.tolist(), d) for t, d, _ in occluded]


def test_extra_targets_are_seen_by_every_required_image(run_full_exact):
    sim = run_full_exact
    haz, haz_r, nav = _ids(sim)
    got = choose_extra_targets(sim.scene, sim.products, haz, haz_r + nav, 6, np.random.default_rng(3))
    assert len(got) == 6
    by = {p.product_id: p for p in sim.products}
    X = np.array([t.xyz_site_m for t in got])
    for pid in [haz] + haz_r + nav:
        p = by[pid]
        _, vis = project_visible(sim.scene, p.model_true_site, p.width, p.height, X)
        assert vis.all(), pid
