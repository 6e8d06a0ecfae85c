"""scipctl.pipeline.predict.approach_search: what the (bearing, standoff) search tried and which rule bound."""

import math

from scipctl.pipeline.predict.approach_search import FOV, ROCK, TARGET, ApproachSearch


def _search(*cands):
    s = ApproachSearch(rock_keep_out_m=0.15, target_keep_out_m=0.25)
    for det, sd, rock, tgt, fov in cands:
        s.add(det, sd, {"min_rock_m": rock, "min_target_m": tgt}, fov, 20.0)
    return s


def test_each_candidate_records_the_constraints_it_breaks_and_a_clear_one_ends_the_refusal():
    s = _search((0.0, 0.8, 0.07, 0.30, 400.0), (0.0, 0.85, 0.12, 0.35, 10.0), (0.0, 0.9, 0.17, 0.40, 300.0))
    assert [t["bound_by"] for t in s.tried] == [[ROCK], [ROCK, FOV], []]
    assert s.found and s.binding() == [] and s.to_dict()["found"]
    assert "the plan kept clears it" in s.describe(ROCK)


def test_binding_is_the_rule_no_candidate_met_else_the_fewest_broken_at_once():
    never_rock = _search((0.0, 0.8, 0.05, 0.30, 400.0), (15.0, 0.8, 0.10, 0.10, 400.0))
    assert never_rock.binding() == [ROCK]
    msg = never_rock.describe(ROCK)
    assert msg.startswith("2 approaches tried (detour +0..+15 deg, standoff 0.80-0.80 m) and none clears rock-keep-out")
    assert "the best comes to 0.10 m (detour +15 deg, standoff 0.80 m)" in msg
    # each rule met by some candidate, never both at once: the candidate with fewest broken names them
    crossed = _search((0.0, 0.8, 0.20, 0.10, 400.0), (0.0, 1.0, 0.05, 0.40, 400.0), (15.0, 0.9, 0.05, 0.10, 400.0))
    assert crossed.binding() == [TARGET]


def test_no_rock_in_the_terrain_is_json_safe():
    s = _search((0.0, 0.8, math.inf, 0.30, 400.0))
    d = s.to_dict()
    assert d["tried"][0]["min_rock_m"] is None and d["found"]


def test_a_rule_some_candidates_meet_is_not_reported_as_unmet():
    # rock-keep-out met at a 45 deg detour, but that plan loses the target from the hazcams; the FOV binds everywhere
    s = _search((0.0, 0.8, 0.12, 0.30, -248.0), (45.0, 1.0, 0.97, 0.50, -300.0))
    assert s.binding() == ["hazcam-fov-final"]
    msg = s.describe(ROCK)
    assert "some clear rock-keep-out, none together with hazcam-fov-final" in msg and "none clears" not in msg
    assert "none clears hazcam-fov-final" in s.describe(FOV)
