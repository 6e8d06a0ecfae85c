"""The rule set: the shipped default file equals the dataclass defaults; a file and options override it;
range errors name the file (or option) and the key."""

import dataclasses
import math

import pytest

from scipctl.errors import InputError
from scipctl.io.rules_file import DEFAULT_RULES_PATH, read_rules_file
from scipctl.pipeline.predict import PredictParams
from scipctl.pipeline.rules import OPTIONS, SPEC, load_rules
from scipctl.pipeline.sequence import FlightRules


def test_the_default_file_gives_exactly_the_dataclass_defaults():
    rs = load_rules()
    assert rs.flight == FlightRules() and rs.predict == PredictParams()
    # every key of the spec is in the default file (a user's file may omit any)
    content = read_rules_file(DEFAULT_RULES_PATH, SPEC)
    assert {s: set(kv) for s, kv in content.values.items()} == {s: set(kv) for s, kv in SPEC.items()}
    assert rs.to_dict()["sha256"] == content.sha256 and rs.overrides == {}


def test_a_user_file_overrides_only_its_keys(tmp_path):
    p = tmp_path / "mine.yaml"
    p.write_text("flight_rules:\n  rock_keep_out_m: 0.05\n  max_tilt_deg: 20\napproach:\n  detour_bearings_deg: [0, 60]\n"
                 "tracking:\n  search_radius_px: {pancam: 200.0, navcam: 90.0, hazcam: 70.0}\n")
    rs = load_rules(p)
    assert rs.flight == dataclasses.replace(FlightRules(), rock_keep_out_m=0.05, max_tilt_rad=math.radians(20))
    a = rs.predict.approach
    assert a.rock_keep_out_m == 0.05 and a.target_keep_out_m == FlightRules().target_keep_out_m  # planned with the rule
    assert a.detour_bearings_rad == (0.0, math.radians(60))
    assert rs.predict.chain.search_radius("pancam") == 200.0
    assert dataclasses.replace(rs.predict, approach=PredictParams().approach, chain=PredictParams().chain) == PredictParams()
    assert rs.source == str(p) and rs.values["flight_rules"]["max_tilt_deg"] == 20


def test_the_arm_margin_key_reaches_the_planner_and_is_recorded(tmp_path):
    p = tmp_path / "mine.yaml"
    p.write_text("approach:\n  arm_margin_sigmas: 3.0\n")
    rs = load_rules(p)
    assert rs.predict.approach.arm_margin_sigmas == 3.0
    assert rs.to_dict()["values"]["approach"]["arm_margin_sigmas"] == 3.0
    assert load_rules().to_dict()["values"]["approach"]["arm_margin_sigmas"] == PredictParams().approach.arm_margin_sigmas


def test_options_override_the_file_and_are_recorded(tmp_path):
    p = tmp_path / "mine.yaml"
    p.write_text("flight_rules:\n  min_p_success: 0.9\n")
    rs = load_rules(p, {"--min-p-success": 0.5, "--rock-keep-out-m": None, "--standoff-m": 0.7})
    assert rs.flight.min_confidence == 0.5 and rs.predict.approach.standoff_m == 0.7
    assert rs.overrides == {"--min-p-success": 0.5, "--standoff-m": 0.7}
    assert rs.to_dict()["values"]["flight_rules"]["min_p_success"] == 0.5
    assert set(OPTIONS) >= {"--min-p-success", "--min-p-simulated", "--rock-keep-out-m"}
    rs = load_rules(None, {"--min-p-simulated": 0.2})
    assert rs.flight.min_p_simulated == 0.2 and rs.to_dict()["values"]["flight_rules"]["min_p_simulated"] == 0.2


@pytest.mark.parametrize("text, key", [
    ("flight_rules:\n  min_p_success: 1.5\n", "flight_rules.min_p_success"),
    ("flight_rules:\n  min_p_simulated: -0.1\n", "flight_rules.min_p_simulated"),
    ("flight_rules:\n  max_tilt_deg: -1\n", "flight_rules.max_tilt_deg"),
    ("approach:\n  detour_bearings_deg: [15, 0]\n", "approach.detour_bearings_deg"),
    ("approach:\n  hazcam_stops_m: [1.4, -1]\n", "approach.hazcam_stops_m"),
    ("approach:\n  arm_margin_sigmas: -1\n", "approach.arm_margin_sigmas"),
    ("arm_workspace:\n  r_max_m: 0.5\n", "arm_workspace.r_max_m"),
    ("rover_body:\n  rear_m: 0.6\n", "rover_body.rear_m"),
    ("uncertainty:\n  n_samples: 0\n", "uncertainty.n_samples"),
    ("tracking:\n  search_radius_px: {pancam: -1.0}\n", "tracking.search_radius_px"),
    ("tracking:\n  handoff_search_radius_px: 0\n", "tracking.handoff_search_radius_px"),
    ("prediction:\n  max_incidence_deg: 95\n", "prediction.max_incidence_deg"),
])
def test_an_out_of_range_value_names_the_file_and_the_key(tmp_path, text, key):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(InputError) as e:
        load_rules(p)
    assert (e.value.product, e.value.field) == (str(p), key)


def test_an_out_of_range_option_names_the_option():
    with pytest.raises(InputError) as e:
        load_rules(None, {"--rock-keep-out-m": -0.1})
    assert (e.value.product, e.value.field) == ("--rock-keep-out-m", "flight_rules.rock_keep_out_m")


def test_the_m2020_builtin_loads_checks_and_keeps_the_defaults_it_does_not_give():
    from scipctl.io.provenance import sha256_file
    from scipctl.io.rules_file import BUILTIN_RULES

    rs = load_rules("m2020")
    assert rs.source == "m2020 (scipctl/data/rules-m2020.yaml)"
    assert rs.to_dict()["sha256"] == sha256_file(BUILTIN_RULES["m2020"]) and "chosen_by" not in rs.to_dict()
    a = rs.predict.approach
    assert (a.arm.r_min_m, a.arm.r_max_m, a.arm.half_width_m) == (1.8, 2.78, 0.6)
    assert rs.flight.min_standoff_m == a.arm.r_min_m
    assert a.pancam_handoff_m > a.hazcam_handoff_m > max(a.hazcam_stops_m) > a.arm.r_max_m
    assert a.body.front_m + rs.flight.target_keep_out_m <= a.arm.r_min_m  # the workspace is clear of the footprint
    # what the file does not give is the default's
    d = load_rules("default")
    assert rs.predict.uncertainty == d.predict.uncertainty and rs.predict.chain == d.predict.chain
    assert rs.flight.min_confidence == d.flight.min_confidence
    assert d.source == load_rules().source == "default (scipctl/data/rules.yaml)"
    assert load_rules("m2020", chosen_by="why").to_dict()["chosen_by"] == "why"


@pytest.mark.parametrize("rover, mission, want", [
    ("m2020 (nasa-jpl/m2020-urdf-models static models + URDF)", "scip-sim", "m2020"),  # the simulator's
    ("from labels", "M2020", "m2020"),  # real Mars 2020 products (the readers' mission name)
    ("from labels", "Mars 2020", "m2020"),
    ("rocky8-sim", "scip-sim", "default"),
    ("from labels", "MSL", "default"),
])
def test_the_builtin_is_chosen_from_the_downlinks_rover(rover, mission, want):
    from types import SimpleNamespace

    from scipctl.pipeline.rules import rules_for_downlink

    name, reason = rules_for_downlink(SimpleNamespace(rover_config=SimpleNamespace(name=rover), mission=mission))
    assert name == want and (rover in reason or mission in reason)


def test_on_the_m2020_rover_the_final_pose_sees_the_target_with_the_m2020_rules_only():
    """The refusal the default rules gave on every Mars 2020 approach (hazcam-fov-final at every standoff) is the
    rules', not the planner's: on flat ground, with the Mars 2020 hazcams, the m2020 rules' first standoff sees
    the target, the default rules' standoffs never do."""
    import numpy as np

    from scipctl.io.m2020_geometry import m2020_rover_config
    from scipctl.pipeline import predict as P
    from scipctl.pipeline.predict.approach_search import FOV
    from tests.io.real_data import real
    from tests.pipeline.predict.helpers import start_pose

    rc = m2020_rover_config(real("12_"))
    target = np.array([8.0, 0.0, 0.0])  # on the ground, 8 m ahead
    base = P.plan_approach(start_pose(), target, None, rc, load_rules("default").predict.approach)
    assert base.search.tried and all(FOV in t["bound_by"] for t in base.search.tried)
    m2020 = load_rules("m2020")
    plan = P.plan_approach(start_pose(), target, None, rc, m2020.predict.approach)
    first = plan.search.tried[0]
    assert first["bound_by"] == [] and first["standoff_m"] == m2020.predict.approach.arm.centre_m
    assert first["hazcam_margin_px"] >= m2020.flight.hazcam_fov_margin_px
