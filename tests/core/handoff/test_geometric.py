"""scipctl/core/handoff/geometric.py: the pure-geometric point is computed once per case and target, shared
by the methods that start from it, and refined by hazcam point stereo."""

import numpy as np

from scipctl.core.handoff import HandoffParams
from scipctl.core.handoff.geometric import pure_geometric, refined_geometric


def test_pure_geometric_is_cached_and_returned_as_a_copy(handoff_scene):
    t = handoff_scene.targets[0]
    case = handoff_scene.cases["near"]
    a = pure_geometric(case, t.nav_uv["near"], case.params)
    a.uv[:] = -1.0
    a.diagnostics["changed"] = True
    b = pure_geometric(case, t.nav_uv["near"], case.params)
    assert np.all(b.uv != -1.0) and "changed" not in b.diagnostics
    r = refined_geometric(case, t.nav_uv["near"], case.params)
    assert r.diagnostics["start_uv"] == b.uv.tolist()


def test_pure_geometric_refinement_is_used_and_without_it_the_dense_answer_is_kept(handoff_scene,
                                                                                    make_handoff_scene):
    t = handoff_scene.targets[1]
    case = handoff_scene.cases["near"]
    r = pure_geometric(case, t.nav_uv["near"], case.params)
    assert r.diagnostics["refined_by"] == "hazcam point stereo"
    assert r.diagnostics["refinement_residual_navcam_px"] <= case.params.geometric_max_residual_px
    dense_only = make_handoff_scene(HandoffParams(haz_point_stereo_window_px=0)).cases["near"]
    d = pure_geometric(dense_only, t.nav_uv["near"], dense_only.params)
    assert d.diagnostics["refined_by"] is None
    np.testing.assert_allclose(d.uv, d.diagnostics["dense_uv"])
