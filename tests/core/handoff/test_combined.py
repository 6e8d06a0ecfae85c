"""scipctl/core/handoff/combined.py: consensus of the tracked methods."""

import numpy as np

from scipctl.core.handoff import Method, run_method


def test_consensus_is_the_mean_of_the_agreeing_candidates(handoff_scene):
    for t in handoff_scene.targets:
        case = handoff_scene.cases["near"]
        r = run_method(case, Method.CONSENSUS, t.nav_uv["near"])
        d = r.diagnostics
        assert d["confident"] is True and len(d["agreeing"]) >= 2
        np.testing.assert_allclose(r.uv, np.mean([d["candidates"][m] for m in d["agreeing"]], axis=0))
        for m in d["agreeing"]:
            alone = run_method(case, m, t.nav_uv["near"])
            np.testing.assert_array_equal(alone.uv, d["candidates"][m])


def test_consensus_falls_back_to_pure_geometric_when_nothing_is_strong_enough(handoff_scene):
    from dataclasses import replace

    t = handoff_scene.targets[0]
    case = handoff_scene.cases["near"]
    r = run_method(case, "consensus", t.nav_uv["near"], replace(case.params, consensus_min_score=1.0))
    pg = run_method(case, "pure-geometric", t.nav_uv["near"])
    assert r.diagnostics["confident"] is False and r.diagnostics["candidates"] == {}
    np.testing.assert_array_equal(r.uv, pg.uv)
