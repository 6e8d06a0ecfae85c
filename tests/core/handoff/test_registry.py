"""Every registered handoff method on the tiny synthetic case with exact truth (tests/core/handoff/conftest.py),
by looping over the registry; the registry itself (names, order, one line per method).

Error model. Models and poses are exact, so a method's error is its own: the
range error of the stereo it uses, carried into the hazcam, plus for the
tracked methods the NCC peak's offset. Stereo's a priori disparity
uncertainty is sigma_d = 0.25 px for point stereo (the figure of
``HandoffParams.registration_disparity_sigma_px``) and, here, 0.5 px for
dense (SGBM) stereo, i.e. sigma_r = r^2 sigma_d / (f b). With 3 sigma:

* kinematic (navcam range): the truth moved along the navcam-left ray by
  3 sigma_r, projected into the hazcam -> ``kin`` px;
* geometric (hazcam range): the truth moved along the hazcam-left ray by
  3 sigma_r moves its navcam projection by dq; the hazcam pixel that
  projects back onto the target moves by J^-1 dq (J: navcam px per hazcam
  px) -> ``geo`` px;
* every answer: + 0.5 px, the rendering (2 x 2 supersampled pixels vs the
  marks' point projection);
* mesh registration: kin + 1 px for ICP started at the exact seed;
* tracked methods (an expected window NCC-tracked): the bound of the
  geometry the window was built from + 1 px (NCC peak and window resampling);
  consensus: the largest of its candidates' bounds.
"""

from __future__ import annotations

import numpy as np
import pytest

from scipctl.core.handoff import (ALL_METHODS, EXTRA_METHODS, METHODS, PAPER_METHODS, HandoffCase, Method,
                                  MethodResult, NoAnswer, run_method)
from scipctl.core.handoff.geometric import haz_to_nav_jacobian
from scipctl.core.handoff.result import answer

POINT_SIGMA_D_PX = 0.25
DENSE_SIGMA_D_PX = 0.5
RENDER_PX = 0.5
ICP_PX = 1.0
TRACK_PX = 1.0


def _kin_px(case: HandoffCase, X_haz, sigma_d_px: float) -> float:
    """Hazcam px moved by the truth ``X_haz`` (3,) displaced 3 sigma_r along the navcam-left ray."""
    nav = case.nav.left_model
    Xn = case.T_haz_nav.inverse().apply(X_haz[None])[0]
    r = float(np.linalg.norm(Xn - nav.C))
    s = 3 * r * r * sigma_d_px / case.nav.dense.focal_baseline_px_m
    X2 = case.T_haz_nav.apply((Xn + s * (Xn - nav.C) / r)[None])[0]
    haz = case.haz.left_model
    return float(np.linalg.norm(haz.project(X2[None])[0] - haz.project(X_haz[None])[0]))


def _geo_px(case: HandoffCase, X_haz, sigma_d_px: float) -> float:
    """Hazcam px moved by the hazcam range error: J^-1 of the navcam px moved by a 3 sigma_r shift along the
    hazcam-left ray."""
    haz = case.haz.left_model
    r = float(np.linalg.norm(X_haz - haz.C))
    s = 3 * r * r * sigma_d_px / case.haz.dense.focal_baseline_px_m
    nav_in_haz = case.nav_model_in_haz()
    dq = nav_in_haz.project((X_haz + s * (X_haz - haz.C) / r)[None])[0] - nav_in_haz.project(X_haz[None])[0]
    J = haz_to_nav_jacobian(case, haz.project(X_haz[None])[0], nav_in_haz)
    assert J is not None
    return float(np.linalg.norm(np.linalg.solve(J, dq)))


def bound_px(method: str, case: HandoffCase, X_haz) -> float:
    """The error model above, for ``method`` on ``case`` at the true point ``X_haz`` (3,) (hazcam rover frame)."""
    kin = _kin_px(case, X_haz, POINT_SIGMA_D_PX) + RENDER_PX
    kin_dense = _kin_px(case, X_haz, DENSE_SIGMA_D_PX) + RENDER_PX
    geo = _geo_px(case, X_haz, POINT_SIGMA_D_PX) + RENDER_PX
    far_window = max(kin, geo)  # far refined-kinematic: the far navcam window, placed by both stereos
    bounds = {
        Method.PURE_KINEMATIC: kin,
        Method.ALT_PURE_KINEMATIC: kin_dense,
        Method.REFINED_KINEMATIC: (kin_dense if case.label == "near" else far_window) + TRACK_PX,
        Method.PURE_GEOMETRIC: geo,
        Method.REFINED_GEOMETRIC: geo + TRACK_PX,
        Method.MESH_REGISTRATION: kin + ICP_PX,
        Method.COARSE_FINE_GEOMETRIC: geo + TRACK_PX,
    }
    bounds[Method.CONSENSUS] = max(bounds[Method.COARSE_FINE_GEOMETRIC], bounds[Method.REFINED_GEOMETRIC],
                                   bounds[Method.REFINED_KINEMATIC], bounds[Method.PURE_GEOMETRIC])
    bounds[Method.SCIP] = max(bounds.values())  # scip answers one of the candidate methods' answers
    return bounds[Method(method)]


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


# Far mesh registration seeded at the exact pose walked 80-108 px off on this scene with OpenCV 4.14's dense stereo
# (rectification sampled on a 1/32 px grid) and stayed within its bound on 5.0: ICP accepts a slide that raises its
# fitness. That is the gross registration failure issue #14 asks to catch or avoid; until then it is a known failure
# here, not a bound to widen.
_KNOWN_FAILURES = {("mesh-registration", "far"): "far ICP can walk off an exact seed (issue #14, item 2)"}


@pytest.mark.parametrize("method,navcam", [
    pytest.param(m, nc, id=f"{m}-{nc}",
                 marks=[pytest.mark.xfail(reason=_KNOWN_FAILURES[(m, nc)], strict=False)] if (m, nc) in _KNOWN_FAILURES
                 else [])
    for m in METHODS for nc in ("near", "far")])
def test_each_method_is_within_its_error_model(handoff_scene, answers, method, navcam):
    case = handoff_scene.cases[navcam]
    for t in handoff_scene.targets:
        r = answers[(t.id, navcam, method)]
        assert r.ok and r.uv is not None, (t.id, r.reason)
        assert (r.method, r.navcam) == (method, navcam) and r.seconds >= 0
        err = float(np.linalg.norm(np.asarray(r.uv) - t.haz_uv))
        b = bound_px(method, case, t.xyz_site_m)  # the near rover frame is the site frame (identity pose)
        assert err <= b, (t.id, err, b)


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
