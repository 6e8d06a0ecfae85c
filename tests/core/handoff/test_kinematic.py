"""scipctl/core/handoff/kinematic.py: the near -> far hint is an argument (no state kept between methods)."""

import numpy as np
import pytest

from scipctl.core.handoff import HandoffParams, Method, run_method
from scipctl.core.handoff.kinematic import pure_kinematic, refined_kinematic
from scipctl.core.handoff.steps import project_haz


def test_far_refined_kinematic_starts_at_the_near_hint(handoff_scene):
    t = handoff_scene.targets[0]
    near, far = handoff_scene.cases["near"], handoff_scene.cases["far"]
    hint = run_method(near, Method.PURE_KINEMATIC, t.nav_uv["near"])
    with_hint = refined_kinematic(far, t.nav_uv["far"], far.params, near_hint=hint)
    assert with_hint.diagnostics["start_uv"] == np.asarray(hint.uv).tolist()
    # no hint (or a failed one): the far kinematic point, as before
    X_far = far.T_haz_nav.apply(far.point_stereo(t.nav_uv["far"]).xyz)
    for h in (None, run_method(near, "pure-kinematic", [-50.0, -50.0])):
        assert h is None or not h.ok
        r = refined_kinematic(far, t.nav_uv["far"], far.params, near_hint=h)
        np.testing.assert_allclose(r.diagnostics["start_uv"], project_haz(far, X_far))
    # the hint is only read: running again with it gives the same answer
    again = run_method(far, Method.REFINED_KINEMATIC, t.nav_uv["far"], near_hint=hint)
    np.testing.assert_array_equal(again.uv, with_hint.uv)


def test_far_window_warp_scale_is_the_papers_window(handoff_scene):
    t = handoff_scene.targets[1]
    far = handoff_scene.cases["far"]
    r = refined_kinematic(far, t.nav_uv["far"], HandoffParams(far_window_warp="scale"))
    assert r.diagnostics["warp"] == "uniform scale" and r.diagnostics["scale"] > 0


def test_pure_kinematic_reports_its_point(handoff_scene):
    t = handoff_scene.targets[0]
    near = handoff_scene.cases["near"]
    r = pure_kinematic(near, t.nav_uv["near"], near.params)
    X = np.asarray(r.diagnostics["xyz_haz_rover_m"])
    np.testing.assert_allclose(project_haz(near, X), r.uv)
    assert np.linalg.norm(X - t.xyz_site_m) < 0.03  # 3 sigma_r of navcam point stereo at 1.6 m (see test_registry)


def test_far_refined_kinematic_with_a_start_far_outside_the_image_has_no_answer(handoff_scene):
    # Session 25: on a degraded m2020 downlink the far branch started from a near hint at (-10311, 2366), where the
    # CAHVORE pixel angle is 0, and the window scale raised ValueError, which stopped the whole downlink. A search
    # region that does not meet the image has nothing to track: NoAnswer, and run_method reports a failed result.
    from scipctl.core.handoff.result import MethodResult, NoAnswer

    t = handoff_scene.targets[0]
    near, far = handoff_scene.cases["near"], handoff_scene.cases["far"]
    hint = run_method(near, Method.PURE_KINEMATIC, t.nav_uv["near"])
    off = MethodResult(hint.method, hint.navcam, True, np.array([-10311.0, 2366.0]), "", dict(hint.diagnostics))
    for warp in ("plane", "scale"):
        with pytest.raises(NoAnswer, match="outside the hazcam image"):
            refined_kinematic(far, t.nav_uv["far"], HandoffParams(far_window_warp=warp), near_hint=off)
    r = run_method(far, Method.REFINED_KINEMATIC, t.nav_uv["far"], near_hint=off)
    assert not r.ok and r.uv is None and "outside the hazcam image" in r.reason
    # just outside the image, within the search radius, it still tracks (the region meets the image)
    R = far.params.search_radius_px
    edge = MethodResult(hint.method, hint.navcam, True, np.array([-R / 2, hint.uv[1]]), "", dict(hint.diagnostics))
    e = run_method(far, Method.REFINED_KINEMATIC, t.nav_uv["far"], near_hint=edge)
    assert "outside the hazcam image" not in (e.reason or "")


def test_search_reaches_image():
    from scipctl.core.handoff.steps import search_reaches_image

    assert search_reaches_image([10, 10], 5, 100, 80)
    assert search_reaches_image([-5, 40], 5, 100, 80) and not search_reaches_image([-5.01, 40], 5, 100, 80)
    assert search_reaches_image([104, 84], 5, 100, 80) and not search_reaches_image([104, 84.01], 5, 100, 80)
