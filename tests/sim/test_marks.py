"""Exact marks: the projection of the true target point through the true model, and visibility (scipctl/sim/marks.py)."""

import numpy as np
import pytest

from scipctl.sim.build import build_run
from scipctl.sim.marks import project_visible

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


def test_traverse_marks_are_exact():
    sim = build_run("traverse", "s1-curved", 1, image_scale=SMALL, supersample=1, render=False)
    dl = sim.downlink
    assert len(dl.targets) == 3
    for tm in dl.targets:
        X = dl.truth_target(tm.id).xyz_site_m
        assert len(tm.marks) >= 8
        for m in tm.marks:
            assert np.hypot(*(_truth_projection(dl, m.product_id, X) - [m.u, m.v])) < 1e-6
