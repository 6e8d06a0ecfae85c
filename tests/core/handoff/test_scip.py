"""scipctl/core/handoff/{evidence,trust_model,scip}.py: evidence of candidate answers on the tiny synthetic case
with exact truth, the trust model's evaluation and JSON round trip, scip's GO rule."""

import json
import math

import numpy as np
import pytest

from scipctl.core.handoff.evidence import CANDIDATE_METHODS, Candidate, Evidence, candidate_evidence, target_views
from scipctl.core.handoff.scip import CANDIDATE_FNS, run_candidates, scip_from_results
from scipctl.core.handoff.scip_params import ScipParams
from scipctl.core.handoff.trust_model import LogisticFit, TrustModel


def constant_model(logit: float, go_min_p: float = 0.5, radii=(1.0, 8.0)) -> TrustModel:
    """A model with no feature: the same probability for every candidate."""
    return TrustModel({}, [], [], [], [LogisticFit(r, [], logit, go_min_p) for r in radii])


def test_candidate_functions_are_the_candidate_methods():
    assert set(CANDIDATE_FNS) == set(CANDIDATE_METHODS)


@pytest.fixture(scope="module")
def correct_and_displaced(handoff_scene):
    """Per target: the evidence of the true hazcam pixel and of the pixel 20 px to its right (both views)."""
    cases = handoff_scene.cases
    hp = cases["near"].params
    out = {}
    for t in handoff_scene.targets:
        views = target_views(cases, t.nav_uv, hp, hp.scip)
        assert set(views) == {"near", "far"}
        cands = [Candidate(np.asarray(t.haz_uv, float), [("refined-geometric", "near")]),
                 Candidate(np.asarray(t.haz_uv, float) + [20.0, 0.0], [("refined-kinematic", "far")])]
        out[t.id] = [candidate_evidence(views, cands, i, hp.scip) for i in range(2)]
    return out


def test_evidence_prefers_the_true_pixel(correct_and_displaced):
    for tid, (good, bad) in correct_and_displaced.items():
        # near always has an expected window; far only where its 256 px navcam has enough dense points on the
        # target's plane (on this scene not on the rock's top): where it has none the features are unknown (NaN)
        assert math.isfinite(good.app_near_score_at) and math.isfinite(good.fb_near_error_px)
        for v in ("near", "far"):
            if math.isnan(getattr(good, f"app_{v}_score_at")):
                assert math.isnan(getattr(good, f"fb_{v}_error_px")) and v == "far"
                continue
            assert getattr(good, f"app_{v}_score_at") > getattr(bad, f"app_{v}_score_at"), (tid, v)
            assert getattr(good, f"fb_{v}_error_px") < getattr(bad, f"fb_{v}_error_px"), (tid, v)
            assert getattr(good, f"geo_{v}_nav_res_px") < getattr(bad, f"geo_{v}_nav_res_px"), (tid, v)
        # exact models and poses: the expected window sits within the tracker's and the stereo's error of the truth
        assert good.app_near_offset_px < 2.0 and good.fb_near_error_px < 2.0, tid
        assert bad.app_near_offset_px > 2.0 or bad.app_near_score_at < good.app_near_score_at - 0.2


def test_registration_check_reaches_the_evidence(handoff_scene):
    """The registration check's evidence in mesh-registration's diagnostics (issue #14 item 2) becomes the
    candidates' reg_* evidence, each from its key of REGISTRATION_CHECK_KEYS (a residual as its absolute value)."""
    from scipctl.core.handoff.evidence import REGISTRATION_CHECK_KEYS
    from scipctl.core.handoff.registration import mesh_registration

    cases = handoff_scene.cases
    hp = cases["near"].params
    t = handoff_scene.targets[0]
    reg = mesh_registration(cases["near"], t.nav_uv["near"], hp)
    check = reg.diagnostics["registration_check"]
    view = target_views(cases, t.nav_uv, hp, hp.scip, {"near": reg})["near"]
    ev = candidate_evidence({"near": view}, [Candidate(np.asarray(t.haz_uv, float), [("mesh-registration", "near")])],
                            0, hp.scip)
    seen = 0
    for suffix, (where, key, absolute) in REGISTRATION_CHECK_KEYS.items():
        v = (reg.diagnostics if where == "diag" else check).get(key)
        got = getattr(ev, f"reg_near_{suffix}")
        if v is None:
            assert math.isnan(got), suffix
            continue
        assert got == (abs(v) if absolute else v), suffix
        seen += where == "check"
    assert seen >= 1  # the check's evidence is there, not only ICP's fitness / RMS
    assert math.isnan(ev.reg_far_fitness)  # no far registration given


def test_packaged_model_gives_the_true_pixel_the_higher_probability(correct_and_displaced):
    from scipctl.io.trust_model import load_packaged_trust_model

    model = load_packaged_trust_model()
    assert model is not None, "scipctl/data/trust_model.json is part of the package"
    for tid, (good, bad) in correct_and_displaced.items():
        p = model.probability([good, bad], 4.0)
        assert p[0] > p[1], (tid, p)


def test_evidence_round_trips_through_json():
    ev = Evidence("mesh-registration", "far", app_near_score_at=0.8, fb_far_error_px=1.5)
    d = json.loads(json.dumps(ev.to_dict()))
    assert d["app_far_score_at"] is None  # NaN is null in JSON
    back = Evidence.from_dict(d)
    assert back.method == "mesh-registration" and back.navcam == "far"
    assert back.app_near_score_at == 0.8 and math.isnan(back.app_far_score_at)
    assert Evidence.from_dict({**d, "a_future_key": 1.0}).fb_far_error_px == 1.5


def test_trust_model_round_trip_and_evaluation():
    model = TrustModel({"zz_a": ("app_near_score_at", "x"), "fb": ("fb_near_error_px", "log1p"),
                        "far": ("navcam", "is_far")},
                       fill=[0.5, 1.0, 0.0], mean=[0.5, 1.0, 0.5], scale=[0.2, 0.5, 0.5],
                       fits=[LogisticFit(4.0, [2.0, -1.0, -0.5], 0.3, 0.9), LogisticFit(1.0, [1.0, -2.0, 0.0], -1.0, 0.95)])
    # through sorted-key JSON, as the model file is written: the coefficients stay with their features
    back = TrustModel.from_dict(json.loads(json.dumps(model.to_dict(), sort_keys=True)))
    assert back.to_dict() == model.to_dict() and back.success_radii_px == (1.0, 4.0)
    ev = Evidence("refined-kinematic", "near", app_near_score_at=0.9, fb_near_error_px=0.5)
    z = np.array([(0.9 - 0.5) / 0.2, (math.log1p(0.5) - 1.0) / 0.5, (0.0 - 0.5) / 0.5])
    p4 = 1 / (1 + math.exp(-(z @ [2.0, -1.0, -0.5] + 0.3)))
    assert back.probability([ev], 4.0)[0] == pytest.approx(p4, rel=1e-12)
    # unknown features sit at the training mean: they move nothing
    unknown = Evidence("refined-kinematic", "near", fb_near_error_px=0.5)
    z0 = np.array([0.0, z[1], z[2]])
    assert back.probability([unknown], 4.0)[0] == pytest.approx(1 / (1 + math.exp(-(z0 @ [2.0, -1.0, -0.5] + 0.3))))
    # between fitted radii: interpolated, monotone; outside: no probability, never a reused one
    p2 = back.probability([ev], 2.0)[0]
    assert back.probability([ev], 1.0)[0] <= p2 <= p4
    assert back.probability([ev], 0.5) is None and back.probability([ev], 8.0) is None
    assert back.go_threshold(4.0) == 0.9 and back.go_threshold(2.0) == 0.95 and back.go_threshold(16.0) is None


@pytest.mark.parametrize("bad", [
    {"features": [["a", "app_near_score_at", "x"]], "fill": [], "mean": [0.0], "scale": [1.0], "fits": []},
    {"features": [["a", "app_near_score_at", "cube"]], "fill": [0.0], "mean": [0.0], "scale": [1.0], "fits": []},
    {"features": {}, "fill": [], "mean": [], "scale": [], "fits": [{"success_px": 4, "coef": [1.0], "intercept": 0,
                                                                    "go_min_p": 0.9}]},
    {"fill": [], "mean": [], "scale": [], "fits": []},
    {"features": {"a": ["app_near_score_at", "x"]}, "fill": [0.0], "mean": [0.0], "scale": [1.0], "fits": []},
])
def test_malformed_models_are_refused(bad):
    with pytest.raises(ValueError):
        TrustModel.from_dict(bad)


def test_scip_go_follows_the_model_and_the_threshold(handoff_scene):
    from dataclasses import replace

    cases = handoff_scene.cases
    t = handoff_scene.targets[0]
    hp = cases["near"].params
    results = [r for nc, c in cases.items() for r in run_candidates(c, t.nav_uv[nc], hp)]
    sure = scip_from_results(cases, t.nav_uv, results, replace(hp, scip=ScipParams(model=constant_model(8.0))))
    assert sure.go and sure.result.method == "scip" and sure.p_success == pytest.approx(1 / (1 + math.exp(-8.0)))
    assert sure.result.navcam in ("near", "far", "both")
    doubt = scip_from_results(cases, t.nav_uv, results, replace(hp, scip=ScipParams(model=constant_model(-8.0))))
    assert not doubt.go and doubt.result.reason == "NO-GO"
    strict = scip_from_results(cases, t.nav_uv, results,
                               replace(hp, scip=ScipParams(model=constant_model(8.0), go_min_p=1.0)))
    assert not strict.go
    none = scip_from_results(cases, t.nav_uv, results, replace(hp, scip=ScipParams(model=None)))
    assert none.p_success is None and not none.go and "no trust model" in none.result.diagnostics["no_probability"]
    outside = scip_from_results(cases, t.nav_uv, results,
                                replace(hp, scip=ScipParams(model=constant_model(8.0), success_px=0.5)))
    assert outside.p_success is None and not outside.go
    # every candidate answer is scored, and scip answers one of them
    assert {s.candidate.sources[0] for s in sure.scored} <= {(r.method, r.navcam) for r in results}
    assert any(np.array_equal(sure.result.uv, s.candidate.uv) for s in sure.scored)


def test_params_check():
    with pytest.raises(ValueError, match="go_min_p"):
        ScipParams(go_min_p=1.5).check()
    with pytest.raises(ValueError, match="agree_px"):
        ScipParams(agree_px=0.0).check()
    with pytest.raises(ValueError, match="model"):
        ScipParams(model="trust_model.json").check()


def test_geometry_veto_turns_go_into_no_go(handoff_scene):
    """``ScipParams.geometry_veto_px``: a GO answer whose hazcam point lands farther than the veto from the navcam
    target in every view is NO-GO, whatever its probability; the answer and p_success stay."""
    from dataclasses import replace

    cases = handoff_scene.cases
    t = handoff_scene.targets[0]
    hp = cases["near"].params
    results = [r for nc, c in cases.items() for r in run_candidates(c, t.nav_uv[nc], hp)]

    def run(veto):
        return scip_from_results(cases, t.nav_uv, results,
                                 replace(hp, scip=ScipParams(model=constant_model(8.0), geometry_veto_px=veto)))

    free = run(None)
    res_px = Evidence.from_dict(free.result.diagnostics["evidence"]).geo_best_nav_res_px
    assert free.go and math.isfinite(res_px) and res_px > 0 and "geometry_veto" not in free.result.diagnostics
    assert run(res_px + 1.0).go  # below the veto: GO
    vetoed = run(res_px / 2)
    assert not vetoed.go and vetoed.result.reason == "NO-GO" and "geometry_veto" in vetoed.result.diagnostics
    assert vetoed.p_success == free.p_success and np.array_equal(vetoed.result.uv, free.result.uv)
    with pytest.raises(ValueError, match="geometry_veto_px"):
        ScipParams(geometry_veto_px=0.0).check()
