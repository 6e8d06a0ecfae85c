"""Every registered handoff method on the tiny synthetic case with exact truth (tests/core/handoff/conftest.py),
by looping over the registry, against its error model (tests/core/handoff/error_model.py); the registry itself
(names, order, one line per method).
"""

from __future__ import annotations

import numpy as np
import pytest

from scipctl.core.handoff import (ALL_METHODS, EXTRA_METHODS, METHODS, PAPER_METHODS, Method, MethodResult, NoAnswer,
                                  run_method)
from scipctl.core.handoff.result import answer
from tests.core.handoff.error_model import bound_px


@pytest.fixture(scope="module")
def answers(handoff_scene):
    """(target, navcam, method) -> MethodResult, run as the pipeline does (the near pure-kinematic hint passed)."""
    out = {}
    for t in handoff_scene.targets:
        hint = run_method(handoff_scene.cases["near"], Method.PURE_KINEMATIC, t.nav_uv["near"])
        for nc, case in handoff_scene.cases.items():
            for m in METHODS:
                out[(t.id, nc, m)] = run_method(case, m, t.nav_uv[nc], near_hint=hint)
    return out


# Methods with a verdict of their own: their answer must be within its bound or flagged (``ok=False``). Far mesh
# registration seeded at the exact pose walked 80-108 px off on this scene with OpenCV 4.14's dense stereo
# (rectification sampled on a 1/32 px grid) and stayed within its bound on 5.0: its coarsest ICP scale slid the
# cloud (issue #14, item 2). The multi-seed registration (core/registration_check.py) keeps the exact seed there
# (0.3 and 0.0 px on 4.14) and flags the target where an equally fitting answer lands 5 px away; on 5.0 it is
# within bound and not flagged.
_WITH_VERDICT = {"mesh-registration"}


@pytest.mark.parametrize("method,navcam", [pytest.param(m, nc, id=f"{m}-{nc}") for m in METHODS
                                           for nc in ("near", "far")])
def test_each_method_is_within_its_error_model(handoff_scene, answers, method, navcam):
    case = handoff_scene.cases[navcam]
    for t in handoff_scene.targets:
        r = answers[(t.id, navcam, method)]
        assert r.uv is not None, (t.id, r.reason)
        assert r.ok or method in _WITH_VERDICT, (t.id, r.reason)
        assert (r.method, r.navcam) == (method, navcam) and r.seconds >= 0
        err = float(np.linalg.norm(np.asarray(r.uv) - t.haz_uv))
        b = bound_px(method, case, t.xyz_site_m)  # the near rover frame is the site frame (identity pose)
        assert err <= b or not r.ok, (t.id, err, b, r.reason)


def test_registry_names_order_and_enum():
    assert list(METHODS) == list(Method) == list(ALL_METHODS)
    assert ALL_METHODS == PAPER_METHODS + EXTRA_METHODS
    assert PAPER_METHODS == ("pure-kinematic", "alt-pure-kinematic", "refined-kinematic", "pure-geometric",
                             "refined-geometric", "mesh-registration")
    assert EXTRA_METHODS == ("coarse-fine-geometric", "consensus", "scip")
    assert Method.PURE_KINEMATIC == "pure-kinematic" and Method("mesh-registration") is Method.MESH_REGISTRATION
    assert all(isinstance(m, str) and type(m) is str for m in ALL_METHODS)  # plain names in records and JSON


def test_a_new_method_is_one_function_and_one_registry_line(handoff_scene):
    """Register a method in a copy of the registry (the real one is untouched) and run it by name."""
    calls = []

    def hazcam_centre(case, nav_uv, params, *, near_hint=None) -> MethodResult:
        calls.append((case.label, tuple(nav_uv), params is case.params, near_hint))
        return answer(np.array([case.haz.width / 2, case.haz.height / 2]), {"toy": True})

    registry = {**METHODS, "hazcam-centre": hazcam_centre}  # the one line
    case = handoff_scene.cases["near"]
    r = run_method(case, "hazcam-centre", [10.0, 20.0], registry=registry)
    assert (r.method, r.navcam, r.ok, r.diagnostics) == ("hazcam-centre", "near", True, {"toy": True})
    np.testing.assert_array_equal(r.uv, [128.0, 128.0])
    assert calls == [("near", (10.0, 20.0), True, None)]
    assert "hazcam-centre" not in METHODS
    with pytest.raises(ValueError, match="unknown handoff method 'hazcam-centre'"):
        run_method(case, "hazcam-centre", [10.0, 20.0])


def test_no_answer_becomes_a_failed_result(handoff_scene):
    def never(case, nav_uv, params, *, near_hint=None):
        raise NoAnswer("nothing here", {"why": 1})

    r = run_method(handoff_scene.cases["far"], "never", [1, 2], registry={"never": never})
    assert (r.method, r.navcam, r.ok, r.uv, r.reason, r.diagnostics) == ("never", "far", False, None,
                                                                         "nothing here", {"why": 1})


def test_case_run_is_the_registry_lookup(handoff_scene, answers):
    """``HandoffCase.run`` (kept for callers that name methods) gives what ``run_method`` gives."""
    t = handoff_scene.targets[0]
    case = handoff_scene.cases["near"]
    for m in (Method.PURE_KINEMATIC, "pure-geometric"):
        a, b = run_method(case, m, t.nav_uv["near"]), answers[(t.id, "near", m)]
        np.testing.assert_array_equal(a.uv, b.uv)
        assert a.diagnostics == b.diagnostics
