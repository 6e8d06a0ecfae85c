"""Flight rules, handoff choice, command list and the three sequence formats (deterministic, SeqN-shaped)."""

import json
import math
import re

import numpy as np
import pytest

from scipctl.pipeline import predict as P
from scipctl.pipeline import sequence as Q
from tests.pipeline.predict.helpers import box_fn, flat, heightfield_source
from tests.pipeline.sequence_doc import RECORD, prediction, sequence_doc

def broken_names(pred, rc, rules=None):
    return sorted(c.rule for c in Q.broken(Q.check_rules(pred, rc, rules)))


# ----------------------------------------------------------------------------- rules


def test_a_good_approach_breaks_no_rule(rc, flat_terrain):
    checks = Q.check_rules(prediction(rc, flat_terrain), rc)
    assert Q.broken(checks) == []
    assert {c.rule for c in checks} >= {"max-drive-distance", "min-standoff", "target-keep-out", "rock-keep-out",
                                        "hazcam-fov-final", "arm-workspace", "final-tilt", "prediction-confidence",
                                        "simulated-risk"}


def test_each_rule_can_be_broken_alone(rc, flat_terrain):
    base = prediction(rc, flat_terrain)
    assert broken_names(base, rc, Q.FlightRules(max_drive_m=5.0)) == ["max-drive-distance"]
    assert broken_names(base, rc, Q.FlightRules(min_confidence=0.99)) == ["prediction-confidence"]
    assert broken_names(base, rc, Q.FlightRules(min_p_simulated=0.99)) == ["simulated-risk"]
    assert broken_names(base, rc, Q.FlightRules(min_standoff_m=0.9)) == ["min-standoff"]
    short_arm = prediction(rc, flat_terrain, approach=P.ApproachParams(standoff_m=0.8, arm=P.ArmWorkspace(0.9, 1.2, 0.4)))
    assert broken_names(short_arm, rc) == ["arm-workspace"]
    close = prediction(rc, flat_terrain, approach=P.ApproachParams(standoff_m=0.5))  # too close: several rules at once
    assert {"min-standoff", "arm-workspace", "target-keep-out"} <= set(broken_names(close, rc))
    # the standoff pinned: the planner may not move it, so the long nose breaks the target keep-out
    long_nose = prediction(rc, flat_terrain, approach=P.ApproachParams(standoff_m=0.8, body=P.RoverBody(front_m=0.7)))
    assert broken_names(long_nose, rc) == ["target-keep-out"]
    high = prediction(rc, flat_terrain, target=np.array([9.0, 0.0, -1.6]))  # a target 1.6 m up: above the hazcams
    assert "hazcam-fov-final" in broken_names(high, rc)


def test_broken_rule_messages_say_what_is_wrong(rc, flat_terrain):
    # a target outside a hazcam image was reported "inside both hazcam images ... (-61 px from the edge)", and a
    # target 3 mm beyond the arm's reach "at (1.00, -0.00) m" against a 0.60-1.00 m workspace
    high = {c.rule: c for c in Q.check_rules(prediction(rc, flat_terrain, target=np.array([9.0, 0.0, -1.6])), rc)}
    fov = high["hazcam-fov-final"]
    assert not fov.ok and "inside" not in fov.message
    assert ("outside a hazcam image" in fov.message and f"{-fov.value:.0f} px beyond its edge" in fov.message
            if np.isfinite(fov.value) else "behind a hazcam" in fov.message), fov.message
    short_arm = prediction(rc, flat_terrain, approach=P.ApproachParams(standoff_m=0.8, arm=P.ArmWorkspace(0.9, 1.2, 0.4)))
    arm = {c.rule: c for c in Q.check_rules(short_arm, rc)}["arm-workspace"]
    assert not arm.ok and f"{arm.value:.3f} m away" in arm.message
    good = {c.rule: c for c in Q.check_rules(prediction(rc, flat_terrain), rc)}["hazcam-fov-final"]
    assert good.ok and "inside both hazcam images" in good.message


def test_the_planner_moves_the_standoff_to_keep_a_long_nose_off_the_target(rc, flat_terrain):
    """Free standoff: the search (centre 0.8 m first, then outwards) keeps the first standoff whose footprint
    (front 0.7 m) stays 0.25 m off the target: 0.95 or 1.0 m, still inside the arm workspace (0.6-1.0 m)."""
    pred = prediction(rc, flat_terrain, approach=P.ApproachParams(body=P.RoverBody(front_m=0.7)))
    assert broken_names(pred, rc) == []
    assert pred.plan.params.final_distance_m >= 0.95 - 1e-9 and pred.plan.detour_rad == 0.0
    assert pred.plan.search.found and pred.plan.search.tried[0]["bound_by"] == ["target-keep-out"]
    # a nose so long that no standoff inside the workspace clears it: refused, and the refusal says so
    longer = prediction(rc, flat_terrain, approach=P.ApproachParams(body=P.RoverBody(front_m=0.8)))
    chk = next(c for c in Q.check_rules(longer, rc) if c.rule == "target-keep-out")
    assert not chk.ok and "none clears target-keep-out" in chk.message and "longer standoff" in chk.message
    assert longer.plan.search.binding() == ["target-keep-out"]


def test_a_target_on_a_rock_is_approached_from_a_standoff_that_clears_the_rock(rc):
    """Issue #15 item 2: the rock the target sits on (0.25 m of it between the target and the rover) breaks the
    rock keep-out (0.15 m) at the workspace centre (footprint front 0.3 m from the target) but not at 0.95 m."""
    T = np.array([9.0, 0.0, 0.3])
    rock = (8.75, -0.25, 9.25, 0.25, 0.3)
    ter = P.Terrain([heightfield_source(box_fn([rock]))], smooth_sigma_px=0)
    pred = prediction(rc, ter, target=T)
    assert broken_names(pred, rc) == []
    s = pred.plan.search
    assert s.tried[0]["standoff_m"] == pytest.approx(0.8) and "rock-keep-out" in s.tried[0]["bound_by"]
    assert pred.plan.clearance["min_rock_m"] >= 0.15 and 0.9 <= pred.plan.params.final_distance_m <= 1.0
    xy = pred.plan.final.T_site_rover.inverse().apply(T)[:2]
    assert pred.plan.params.arm.contains(xy[None])[0]
    # the pinned centre standoff is not moved: the same rock then breaks the rule
    pinned = prediction(rc, ter, target=T, approach=P.ApproachParams(standoff_m=0.8, detour_bearings_rad=(0.0,)))
    assert broken_names(pinned, rc) == ["rock-keep-out"]
    # a rock too wide for any standoff or bearing: refused, naming the rule, the search and what would satisfy it
    wide = P.Terrain([heightfield_source(box_fn([(8.5, -0.5, 9.5, 0.5, 0.3)]))], smooth_sigma_px=0)
    blocked = prediction(rc, wide, target=T)
    chk = next(c for c in Q.check_rules(blocked, rc) if c.rule == "rock-keep-out")
    assert not chk.ok and blocked.plan.search.binding() == ["rock-keep-out"]
    n = len(P.ApproachParams().detour_bearings_rad) * len(P.standoff_candidates(P.ApproachParams()))
    assert f"{n} approaches tried" in chk.message and "none clears rock-keep-out" in chk.message
    assert "another approach side" in chk.message


def test_rock_beside_the_final_pose_breaks_the_rock_keep_out(rc):
    rock = (8.0, 0.45, 8.4, 0.7, 0.3)  # 5 cm from the final footprint's side
    ter = P.Terrain([heightfield_source(box_fn([rock]))], smooth_sigma_px=0)
    pred = prediction(rc, ter, approach=P.ApproachParams(detour_bearings_rad=(0.0,)))
    assert broken_names(pred, rc) == ["rock-keep-out"]
    chk = next(c for c in Q.check_rules(pred, rc) if c.rule == "rock-keep-out")
    assert chk.value == pytest.approx(0.05, abs=0.03)


def test_steep_or_unknown_terrain_at_the_final_pose_breaks_the_tilt_rule(rc):
    slope = math.tan(math.radians(20.0))
    ter = P.Terrain([heightfield_source(lambda X, Y: slope * X)], smooth_sigma_px=0)
    steep = prediction(rc, ter, target=np.array([9.0, 0.0, -slope * 9.0]))
    chk = next(c for c in Q.check_rules(steep, rc) if c.rule == "final-tilt")
    assert not chk.ok and chk.value == pytest.approx(math.radians(20.0), abs=1e-3)
    unknown = prediction(rc, None)
    chk = next(c for c in Q.check_rules(unknown, rc) if c.rule == "final-tilt")
    assert not chk.ok and "unknown" in chk.message


# ----------------------------------------------------------------------------- handoff choice


def test_choose_handoff_from_results_and_default():
    rows = [
        {"method": "pure-kinematic", "navcam": "near", "cases": 6, "answered": 6, "success_rate": 0.2, "all": {"mean_px": 9.0}},
        {"method": "pure-geometric", "navcam": "near", "cases": 6, "answered": 6, "success_rate": 0.3, "all": {"mean_px": 5.0}},
        {"method": "refined-geometric", "navcam": "near", "cases": 6, "answered": 5, "success_rate": 0.8, "all": {"mean_px": 30.0}},
        {"method": "refined-kinematic", "navcam": "far", "cases": 6, "answered": 6, "success_rate": 1.0, "all": {"mean_px": 1.0}},
    ]
    ch = Q.choose_handoff(rows, "best-single")
    assert ch["primary"] == "refined-geometric" and ch["fallback"] == "pure-geometric" and ch["navcam"] == "near"
    d = Q.choose_handoff(None, "best-single")
    assert (d["primary"], d["fallback"]) == Q.DEFAULT_HANDOFF and "paper" in d["basis"]
    assert "no handoff results" in d["basis"]
    # results saved, but none of a near-navcam method (a scip-only or far-only run): said so, not "no results"
    d = Q.choose_handoff([r for r in rows if r["navcam"] == "far"], "best-single")
    assert (d["primary"], d["fallback"]) == Q.DEFAULT_HANDOFF and "hold no near-navcam method" in d["basis"]


def test_the_default_handoff_is_scip_with_its_go_threshold_and_saved_results_quoted():
    # issue #14: scip, the recommended handoff, is the sequence's default (it uplinked a paper method before,
    # because scip's Table 1 row has navcam "any" and the choice kept near-navcam rows only)
    rows = [{"method": "scip", "navcam": "any", "cases": 3, "answered": 3, "success_rate": 2 / 3, "all": {"mean_px": 2.0}},
            {"method": "pure-geometric", "navcam": "near", "cases": 3, "answered": 3, "success_rate": 1.0}]
    for r in (rows, None):
        d = Q.choose_handoff(r, success_px=4.0, min_p_success=0.9)
        assert (d["primary"], d["fallback"], d["navcam"]) == ("scip", None, "both")
        assert (d["success_px"], d["min_p_success"]) == (4.0, 0.9) and "NO-GO halts before the arm" in d["basis"]
    assert "saved results: 67% of 3 within 4 px" in Q.choose_handoff(rows, success_px=4.0)["basis"]
    assert Q.choose_handoff(rows)["min_p_success"] is None  # no threshold known: never GO
    with pytest.raises(ValueError, match="not one of"):
        Q.choose_handoff(rows, "consensus")


# ----------------------------------------------------------------------------- commands and formats


def test_commands_cover_every_stop_and_end_with_the_arm(rc, flat_terrain):
    pred, doc = sequence_doc(rc, flat_terrain)
    stems = [c["stem"] for c in doc["commands"]]
    assert stems[0] == "SCIP_BEGIN" and stems[-1] == "SCIP_END" and stems[-2] == "ARM_PLACE_AT_TARGET"
    for st in pred.plan.stops[1:]:
        imgs = [c for c in doc["commands"] if c["stop"] == st.index and c["stem"] == "IMG_STEREO"]
        assert [a["args"][0]["value"] for a in imgs] == [sh.camera.upper() for sh in st.cameras]
    assert stems.count("TRK_HANDOFF_SCALED") == 1 and stems.count("TRK_HANDOFF_SCIP") == 1
    assert "TRK_HANDOFF_NAVCAM_HAZCAM" not in stems  # scip, not a paper method, by default
    assert stems.index("TRK_HANDOFF_SCIP") < stems.index("ARM_PLACE_AT_TARGET")
    assert stems.count("DRV_TURN_TO_TARGET") == 1
    # the waypoints are the planned stops before the turn; after it the rover closes in on the tracked target
    wps = [c for c in doc["commands"] if c["stem"] == "DRV_GOTO_WAYPOINT"]
    before = [s for s in pred.plan.stops[1:] if s.kind not in ("hazcam", "final")]
    assert len(wps) == len(before)
    for c, s in zip(wps, before):
        assert [c["args"][0]["value"], c["args"][1]["value"]] == pytest.approx(s.T_site_rover.t[:2].tolist(), abs=1e-6)
    appr = [c for c in doc["commands"] if c["stem"] == "DRV_APPROACH_TARGET"]
    assert appr[-1]["args"][0]["value"] == pytest.approx(pred.plan.params.final_distance_m)
    # exposures from today's images; AUTO where there is none
    exp = {c["args"][0]["value"]: c["args"][1] for c in doc["commands"] if c["stem"] == "IMG_STEREO"}
    assert exp["PANCAM"]["value"] == 12.5 and exp["NAVCAM"] == {"name": "exposure_ms", "type": "enum", "value": "AUTO"}
    # relative time tags add up to the start times
    t = 0
    for c in doc["commands"]:
        h, m, s = (int(x) for x in c["time_tag"][1:].split(":"))
        t += 3600 * h + 60 * m + s
        assert abs(t - c["start_s"]) <= len(doc["commands"])  # whole seconds, rounded up per command


def test_formats_are_deterministic_and_consistent(rc, flat_terrain):
    _, d1 = sequence_doc(rc, flat_terrain)
    _, d2 = sequence_doc(rc, P.Terrain([heightfield_source(flat)], smooth_sigma_px=0))  # recomputed from scratch
    for name, fmt in Q.FORMATTERS.items():
        assert fmt(d1) == fmt(d2), name
    assert json.loads(Q.format_json(d1)) == d1
    text = Q.format_text(d1)
    for r in d1["rules"]:
        assert r["rule"] in text
    assert Q.NOTIONAL in Q.format_seqn(d1) and Q.NOTIONAL in text and d1["notional"] == Q.NOTIONAL
    # the plain text, too, says how it was made: version, command line, every input's hash
    pv = d1["provenance"]
    assert f"made by scipctl {pv['version']}: " in text
    assert all(v["sha256"] in text for v in pv["inputs"].values())


_ARG = r'(?:-?\d+(?:\.\d+)?|"(?:[^"\\]|\\.)*"|[A-Za-z][A-Za-z0-9_-]*)'
_CMD = re.compile(r'^R\d\d:\d\d:\d\d [A-Za-z][A-Za-z0-9_-]*(?: ' + _ARG + r')*(?: # .*)?$')


def test_seqn_text_follows_the_notation(rc, flat_terrain):
    _, doc = sequence_doc(rc, flat_terrain)
    lines = Q.format_seqn(doc).splitlines()
    kinds = []
    for ln in lines:
        if ln.startswith("#"):
            kinds.append("comment")
        elif ln.startswith("@ID "):
            assert json.loads(ln[4:]) == doc["sequence_id"]
            kinds.append("id")
        elif ln.startswith("@METADATA "):
            m = re.match(r'^@METADATA ("(?:[^"\\]|\\.)*") (.*)$', ln)
            assert m, ln
            json.loads(m.group(1))
            json.loads(m.group(2))
            kinds.append("meta")
        else:
            assert _CMD.match(ln), ln
            kinds.append("cmd")
    # order: comments, @ID, one block of @METADATA, then commands (with comment lines between them)
    first_cmd = kinds.index("cmd")
    assert kinds.index("id") < kinds.index("meta") < first_cmd
    meta = [i for i, k in enumerate(kinds) if k == "meta"]
    assert meta == list(range(meta[0], meta[-1] + 1)) and meta[-1] == first_cmd - 1
    assert set(kinds[first_cmd:]) <= {"cmd", "comment"}
    assert kinds.count("cmd") == len(doc["commands"])
    assert lines[first_cmd].startswith("R00:00:00 SCIP_BEGIN")


def test_time_tags():
    assert Q.time_tag(0) == "R00:00:00"
    assert Q.time_tag(59.2) == "R00:01:00"
    assert Q.time_tag(3725) == "R01:02:05"


def test_a_low_confidence_refusal_names_the_weakest_stop_and_what_would_raise_it(rc, flat_terrain):
    from dataclasses import replace

    pred = prediction(rc, flat_terrain, confidence=0.3)
    risks = [P.Risk(4, "navcam", "view", 0.35, ["out of field of view (P in view 0.40)"]),
             P.Risk(6, "hazcam", "view", 0.6, ["occlusion (P visible 0.60)"])]
    chk = next(c for c in Q.check_rules(replace(pred, risks=risks), rc) if c.rule == "prediction-confidence")
    assert not chk.ok and "weakest: stop 4 navcam view P 0.35" in chk.message and "closer stop" in chk.message
    fine = next(c for c in Q.check_rules(replace(pred, confidence=0.9, risks=risks), rc)
                if c.rule == "prediction-confidence")
    assert fine.ok and "weakest" not in fine.message


def test_the_two_probability_rules_read_their_own_probability(rc, flat_terrain):
    """prediction-confidence reads the calibrated P(success) (``confidence``), simulated-risk the prediction's own
    simulated P (``p_simulated``), each against its own limit; a refusal of the second names the weakest stop."""
    from dataclasses import replace

    pred = prediction(rc, flat_terrain)
    risks = [P.Risk(4, "navcam", "view", 0.35, ["out of field of view (P in view 0.40)"])]
    calibrated_low = replace(pred, confidence=0.45, p_simulated=0.99, calibration="test")
    assert broken_names(calibrated_low, rc) == ["prediction-confidence"]
    chk = next(c for c in Q.check_rules(calibrated_low, rc) if c.rule == "prediction-confidence")
    assert "calibrated against the chain" in chk.message
    simulated_low = replace(pred, confidence=0.6, p_simulated=0.3, risks=risks)
    assert broken_names(simulated_low, rc) == ["simulated-risk"]
    chk = next(c for c in Q.check_rules(simulated_low, rc) if c.rule == "simulated-risk")
    assert chk.value == 0.3 and chk.limit == 0.7 and "weakest: stop 4 navcam view P 0.35" in chk.message
    assert broken_names(simulated_low, rc, Q.FlightRules(min_p_simulated=0.25)) == []


def test_the_arm_margin_rule_is_advisory_and_names_what_the_candidates_with_the_margin_broke(rc, flat_terrain):
    # a 0.3 m rock beside the direct line just before the target: only the workspace's edge clears rock-keep-out
    ter = P.Terrain([heightfield_source(box_fn([(8.65, 0.25, 8.8, 0.5, 0.3)]))], smooth_sigma_px=0)
    up = P.UncertaintyParams()
    pred = prediction(rc, ter, approach=P.ApproachParams(detour_bearings_rad=(0.0,)), uncertainty=up)
    checks = {c.rule: c for c in Q.check_rules(pred, rc)}
    c = checks["arm-margin"]
    assert not c.ok and not c.blocking and c.value < c.limit == pred.plan.arm_margin.margin_m
    assert "the candidates with that room break rock-keep-out" in c.message
    assert all(x.ok for x in checks.values() if x.blocking)  # the edge plan itself breaks no flight rule
    ok = {c.rule: c for c in Q.check_rules(prediction(rc, flat_terrain, uncertainty=up), rc)}["arm-margin"]
    assert ok.ok and ok.value >= ok.limit
    # in mm: "needs 0.001 m (2 x 0.000 m)" did not add up
    am = prediction(rc, flat_terrain, uncertainty=up).plan.arm_margin
    assert f"needs {1000 * am.margin_m:.1f} mm ({am.n_sigma:g} x {1000 * am.sigma_m:.1f} mm)" in ok.message
    # without the error model (a pinned standoff, or no uncertainty) there is no such rule
    assert "arm-margin" not in {c.rule for c in Q.check_rules(prediction(rc, flat_terrain), rc)}
