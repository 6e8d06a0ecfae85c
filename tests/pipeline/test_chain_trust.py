"""Trust along the chain: scoring steps, the advice at a NO-GO step and the chain's verdict (hand-made chains;
the bundled sols' chains are in test_chain.py)."""

import numpy as np
import pytest

from scipctl.core.step_trust import STEP_FEATURES, StepTrustModel
from scipctl.pipeline.chain import ChainStep
from scipctl.pipeline.chain_trust import (FALL_BACK, NEW_IMAGE, REDESIGNATE, advice_for, chain_verdict,
                                          score_hazcam_handoffs, score_steps,
                                          step_evidence)


def _step(pos, camera, kind, status="confirmed", ok=True, uv=(10.0, 10.0), final=False, ncc=0.8, **extra):
    x = {"px_mm": 1.5, "scale": 2.0}
    if kind != "designate" and camera != "hazcam":
        x.update({"feature_status": status, "feature_local_inliers": 20, "feature_inliers": 40,
                  "feature_confirmed": 3 if status == "confirmed" else 0, "template": "plane, feature-guided"})
    if camera == "hazcam":
        x["final"] = final
    x.update(extra)
    return ChainStep((1, pos), camera, f"{camera}-{pos}", kind, None, None if uv is None else list(uv), [10.0, 10.0],
                     None if uv is None else 0.5, ncc, 2.0 if ok else None, None, None, None, ok, "", x)


def _chain():
    """designate (pancam, stop 0), pancam track and navcam handoff (stop 1), navcam track (stop 2), navcam track
    and the hazcam handoff (stop 3)."""
    return [_step(0, "pancam", "designate"), _step(1, "pancam", "track"), _step(1, "navcam", "handoff"),
            _step(2, "navcam", "track"), _step(3, "navcam", "track"), _step(3, "hazcam", "handoff", final=True)]


# a model that trusts exactly the steps the chain marked ok (a large weight on the ok flag)
OK_MODEL = StepTrustModel({"ok": STEP_FEATURES["ok"]}, [0.5], [0.5], [0.5], [10.0], 0.0, 0.9, 6.5)


def _score(steps, haz_go=True):
    steps[-1].p_success, steps[-1].go = (0.99, True) if haz_go else (0.3, False)
    score_steps(steps, OK_MODEL)
    return steps


def test_every_step_scored_and_the_chain_go_when_all_are():
    steps = _score(_chain())
    assert steps[0].p_success is None and steps[0].go  # no designation trust recorded: taken as given
    for s in steps[1:5]:
        assert s.p_success == pytest.approx(1 / (1 + np.exp(-10.0 * (1 - 0.5) / 0.5))) and s.go and s.advice is None
    assert steps[-1].p_success == 0.99 and steps[-1].go  # scip's, kept
    v = chain_verdict(steps)
    assert v.go and v.step is None and v.advice is None


def _designation(p_ok, go, veto=None):
    return {"p_ok": p_ok, "go": go, "tolerance_pct": 1.0, "go_min_p": 0.93, "veto": veto}


def test_the_designation_step_carries_the_designation_models_trust():
    """Step 0 takes ``extra["designation"]`` (what ``scipctl designate`` would say of the same point stereo): its
    p_ok and GO. A NO-GO designation makes the chain NO-GO at step 0 and advises re-designating; a veto (no texture)
    is NO-GO whatever p_ok says."""
    steps = _chain()
    steps[0].extra["designation"] = _designation(0.97, True)
    _score(steps)
    assert steps[0].p_success == 0.97 and steps[0].go and steps[0].advice is None
    assert chain_verdict(steps).go
    for d in (_designation(0.61, False), _designation(0.99, False, veto="the window has no texture to match")):
        steps = _chain()
        steps[0].extra["designation"] = d
        _score(steps)
        assert steps[0].p_success == d["p_ok"] and not steps[0].go and steps[0].advice == REDESIGNATE
        v = chain_verdict(steps)
        assert not v.go and v.step == 0 and v.advice == REDESIGNATE and "pancam designate" in v.why
    # without a step model the designation is still scored and advised
    steps = _chain()
    steps[0].extra["designation"] = _designation(0.61, False)
    score_steps(steps, None)
    assert steps[0].p_success == 0.61 and not steps[0].go and steps[0].advice == REDESIGNATE


def test_a_designation_without_its_trust_is_taken_as_given():
    """A record made before the designation was scored (or with no designation model): p None, GO."""
    steps = _score(_chain())
    assert steps[0].p_success is None and steps[0].go and steps[0].advice is None
    steps = _chain()
    steps[0].extra["designation"] = _designation(None, False)  # a model that could not score it
    _score(steps)
    assert steps[0].p_success is None and steps[0].go


def test_a_go_closure_answer_stands_over_a_nogo_designation():
    """The closure model's p is for the final pixel itself (re-found from the 4.5 m reference in the final hazcam
    image): a GO closure makes the chain GO as it does over a NO-GO reference step; a NO-GO closure leaves the
    designation's NO-GO to decide."""
    for closure_go, chain_go in ((True, True), (False, False)):
        steps = _chain()
        steps[0].extra["designation"] = _designation(0.5, False)
        _score(steps)
        steps[-1].extra.update({"answer": "closure", "closure": {"reference_step": 1}})
        steps[-1].p_success, steps[-1].go = (0.97, True) if closure_go else (0.6, False)
        v = chain_verdict(steps)
        assert v.go == chain_go and (chain_go or v.step == 0)


def test_first_track_without_a_confirmed_match_says_re_designate():
    steps = _chain()
    steps[1] = _step(1, "pancam", "track", status="failed", ok=False)
    _score(steps)
    assert not steps[1].go and steps[1].advice == REDESIGNATE
    v = chain_verdict(steps)
    assert not v.go and v.step == 1 and v.advice == REDESIGNATE and "pancam track" in v.why


def test_a_lost_step_has_p_zero():
    steps = _chain()
    steps[3] = _step(2, "navcam", "track", uv=None, ok=False)
    _score(steps)
    assert steps[3].p_success == 0.0 and not steps[3].go and steps[3].advice == NEW_IMAGE
    assert chain_verdict(steps).step == 3


def test_intermediate_step_says_new_image_and_the_stop_at_the_hazcam_says_fall_back():
    steps = _chain()
    steps[3] = _step(2, "navcam", "track", status="unconfirmed", ok=False)
    _score(steps)
    assert steps[3].advice == NEW_IMAGE
    steps = _chain()
    steps[4] = _step(3, "navcam", "track", ok=False)
    _score(steps)
    assert steps[4].advice == FALL_BACK
    assert chain_verdict(steps).advice == FALL_BACK


def test_a_nogo_hazcam_handoff_says_fall_back():
    steps = _score(_chain(), haz_go=False)
    assert steps[-1].advice == FALL_BACK
    v = chain_verdict(steps)
    assert not v.go and v.step == 5 and v.advice == FALL_BACK


def test_a_chain_with_no_hazcam_answer_is_nogo():
    steps = _score(_chain())[:-1]
    v = chain_verdict(steps)
    assert not v.go and v.advice == FALL_BACK and "no hazcam answer" in v.why


def test_an_earlier_hazcam_stop_does_not_decide_the_chain():
    """With a handoff at every hazcam stop, only the final one is on the chain's path."""
    steps = _chain()
    steps.insert(4, _step(2, "hazcam", "handoff", final=False))
    steps[4].p_success, steps[4].go = 0.1, False
    _score(steps)
    assert chain_verdict(steps).go


def test_without_a_model_tracking_steps_are_unscored_and_nogo():
    steps = _chain()
    score_steps(steps, None)
    assert all(s.p_success is None and not s.go for s in steps[1:5])
    assert not chain_verdict(steps).go


def test_evidence_counts_the_earlier_steps():
    steps = _chain()
    steps[1] = _step(1, "pancam", "track", ok=False, ncc=0.4)
    ev = step_evidence(steps, 3)
    assert ev.kind == "navcam-track" and ev.prior_steps == 2 and ev.prior_flagged == 1 and ev.prior_min_ncc == 0.4
    assert ev.status_confirmed == 1.0 and ev.px_mm == 1.5 and ev.zoom == 2.0
    assert advice_for(steps, 1) == NEW_IMAGE  # confirmed features, only the flag: not a re-designation


def test_evidence_of_a_confirmed_step_says_how_far_ncc_moved_the_feature_position_and_how_many_agreed():
    """refine_px: |NCC peak - feature model position| of the winning candidate; pooled: the candidates pooled. Only
    a confirmed step has them (an unconfirmed step's NCC peak was elsewhere; NaN: the model's fill)."""
    steps = _chain()
    steps[1] = _step(1, "pancam", "track", coarse_uv=[100.0, 50.0], ncc_uv=[103.0, 54.0], feature_pooled=2)
    ev = step_evidence(steps, 1)
    assert ev.refine_px == 5.0 and ev.pooled == 2.0
    steps[1] = _step(1, "pancam", "track", status="unconfirmed", coarse_uv=[100.0, 50.0], ncc_uv=[103.0, 54.0],
                     feature_pooled=4)
    ev = step_evidence(steps, 1)
    assert np.isnan(ev.refine_px) and np.isnan(ev.pooled)
    assert np.isnan(step_evidence(_chain(), 1).refine_px)  # no positions recorded


def test_a_closure_answer_is_judged_without_the_navcam_steps_it_skips():
    """When the final answer is the closure's (``extra["answer"] == "closure"``, found from its reference step
    across the navcam tracks), a NO-GO navcam track between the reference and the final step does not decide the
    chain. A GO closure makes the chain GO even below a NO-GO reference (the closure model weighs the reference's
    own p); a NO-GO closure leaves the verdict to the first NO-GO step, the reference's if it is one."""
    steps = _chain()
    steps[3] = _step(2, "navcam", "track", status="failed", ok=False)
    _score(steps)
    assert not chain_verdict(steps).go and chain_verdict(steps).step == 3  # the handoff's answer depends on it
    steps[-1].extra.update({"answer": "closure", "closure": {"reference_step": 1, "status": "confirmed"}})
    v = chain_verdict(steps)
    assert v.go and v.step is None
    steps[1] = _step(1, "pancam", "track", status="unconfirmed", ok=False)  # the reference itself NO-GO
    _score(steps)
    steps[-1].extra.update({"answer": "closure", "closure": {"reference_step": 1, "status": "confirmed"}})
    assert not steps[1].go and chain_verdict(steps).go  # the closure is GO: its model weighed the reference
    steps[-1].go = False
    v = chain_verdict(steps)
    assert not v.go and v.step == 1 and v.advice == REDESIGNATE  # a NO-GO closure: the first NO-GO step decides
    steps = _score(_chain(), haz_go=False)
    steps[-1].extra.update({"answer": "closure", "closure": {"reference_step": 1, "status": "confirmed"}})
    assert chain_verdict(steps).step == 5


def _haz_chain(navcam="near"):
    """_chain() with the hazcam handoff's record naming its input: the near navcam track at its stop (step 4) or,
    from far, the navcam track at stop 2 (step 3), as chain_handoff.hazcam_handoff records them."""
    steps = _chain()
    steps[-1].extra.update({"method": "scip", "navcam": navcam, "reference": "navcam-3",
                            "far_reference": "navcam-2" if navcam in ("far", "both") else None})
    return steps


@pytest.mark.parametrize("navcam, src", [("near", 4), ("far", 3)])
def test_hazcam_handoff_p_is_scips_times_its_navcam_inputs(navcam, src):
    """The chain's hazcam handoff answers for the target, not for the navcam pixel it was given: p = scip's x the
    input navcam step's, GO only when both are; scip's own kept in extra."""
    steps = _score(_haz_chain(navcam))
    steps[src].p_success = 0.6  # the input step, as the step model might score it (still GO in the verdict's eyes)
    score_hazcam_handoffs(steps)
    h = steps[-1]
    assert h.extra["scip_p_success"] == 0.99 and h.extra["scip_go"] is True
    assert h.extra["navcam_p_success"] == 0.6
    assert h.p_success == pytest.approx(0.99 * 0.6, rel=1e-15)
    assert h.go  # both GO
    steps[src].go = False
    h.extra.pop("scip_p_success")  # score afresh
    h.p_success, h.go = 0.99, True
    score_hazcam_handoffs(steps)
    assert not h.go and h.advice == FALL_BACK  # its input is NO-GO: so is the answer


def test_hazcam_handoff_from_both_views_takes_the_better_input():
    steps = _score(_haz_chain("both"))
    steps[3].p_success, steps[4].p_success = 0.3, 0.8
    score_hazcam_handoffs(steps)
    assert steps[-1].extra["navcam_p_success"] == 0.8 and steps[-1].p_success == pytest.approx(0.99 * 0.8)


def test_hazcam_handoff_without_a_scored_input_is_unknown_and_no_go():
    steps = _haz_chain("near")
    steps[-1].p_success, steps[-1].go = 0.99, True
    score_steps(steps, None)  # no step model: the navcam steps have no p
    score_hazcam_handoffs(steps)
    assert steps[-1].p_success is None and not steps[-1].go and steps[-1].extra["scip_p_success"] == 0.99
    # scored once: a second call leaves it as it is
    score_hazcam_handoffs(steps)
    assert steps[-1].extra["scip_p_success"] == 0.99


def test_a_handoff_scip_did_not_score_is_left_alone():
    steps = _chain()  # no method / navcam recorded, p None (another method)
    score_steps(steps, OK_MODEL)
    score_hazcam_handoffs(steps)
    assert steps[-1].p_success is None and "scip_p_success" not in steps[-1].extra
