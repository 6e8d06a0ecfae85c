"""The measurement scripts that run parts of recorded chains again (docs/scripts/closure_references.py,
docs/scripts/first_track_rerun.py, docs/scripts/designation_in_chains.py): on chains of the bundled paper-s1-straight, written as a campaign records
them, each must give the recorded answers back before its variants mean anything."""

import json
from pathlib import Path

import numpy as np
import pytest

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import run_chain
from scipctl.pipeline.chain_trust import chain_verdict
from tests.doc_scripts import load

ROOT = Path(__file__).resolve().parents[2]
SOL = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"


@pytest.fixture(scope="module")
def camp(tmp_path_factory):
    """A campaign folder with the default chains of t1 (its 4.5 m pancam track fails: the closure starts from the
    navcam handoff) and t2 (a confirmed pancam track), records as ``scipctl campaign`` writes them."""
    dl = read_downlink(SOL)
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    lines = [{"kind": "header", "status": "ok", "family": "default", "job": {"path": str(SOL)}}]
    feats = {}
    for tid in ("t1", "t2"):
        mk = dl.target(tid).mark_in(start.product_id)
        steps = run_chain(dl, start, [mk.u, mk.v], target_id=tid, feature_cache=feats)
        lines.append({"kind": "chain", "record": {"target": tid, "go": chain_verdict(steps).go,
                                                  "steps": [s.to_dict() for s in steps]}})
    out = tmp_path_factory.mktemp("camp")
    (out / "records").mkdir()
    (out / "records" / "paper-s1-straight.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    return out


def test_closures_from_each_reference_give_the_recorded_one_back(camp, tmp_path, capsys):
    cr = load("closure_references")
    out = tmp_path / "rows.jsonl"
    assert cr.main(["run", str(camp), str(out)]) == 0
    assert json.loads(capsys.readouterr().err) == {"chains": 2, "reproduced": 2, "moved": 0}
    rows = {r["target"]: r for r in map(json.loads, out.read_text().splitlines())}
    # t1: no trusted pancam track, so the chain's closure came from the navcam handoff; t2 from the pancam track
    assert rows["t1"]["pancam"]["step"] is None and rows["t1"]["used_step"] == rows["t1"]["navcam"]["step"]
    assert rows["t2"]["used_step"] == rows["t2"]["pancam"]["step"] == 1
    assert rows["t1"]["designation"]["step"] == rows["t2"]["designation"]["step"] == 0
    s = cr.score(list(rows.values()))
    today = s["rules"][0]
    assert today["order"] == ["pancam", "navcam"]
    # today's order is the chain's own answer, chain by chain
    assert today["won"] == today["lost"] == 0 and today["within"] == s["own_within"]
    for r in rows.values():
        err, _ = cr.rule_error(r, ("pancam", "navcam"))
        assert err == pytest.approx(r["final_px"], abs=1e-9)


def test_the_first_track_again_gives_the_recorded_pixel_back(camp, tmp_path, capsys):
    ft = load("first_track_rerun")
    out = tmp_path / "rows.jsonl"
    assert ft.main(["run", str(camp), str(out), 'h26={"half": 26}']) == 0
    assert json.loads(capsys.readouterr().err) == {"tracks": 2, "reproduced": 2, "moved": 0}
    rows = {r["target"]: r for r in map(json.loads, out.read_text().splitlines())}
    assert rows["t1"]["default"]["status"] == rows["t1"]["recorded_status"] == "failed"
    assert rows["t2"]["default"]["uv"] == rows["t2"]["recorded_uv"]
    assert rows["t2"]["default"]["status"] == "confirmed" and set(rows["t2"]) >= {"default", "h26"}
    s = ft.score(list(rows.values()))
    assert s["tracks"] == 2 and s["variants"]["default"]["confirmed"] == 1
    assert s["variants"]["h26"]["won_4mm"] + s["variants"]["h26"]["lost_4mm"] <= 2


def test_the_ncc_median_options_on_the_first_track(camp, tmp_path, capsys):
    """``ChainParams.ncc_median_prev_px`` (the feature step's NCC on median-filtered images) and ``ncc_median_find``
    (the median finds the peak, the unfiltered NCC places it) on the bundled sol's first pancam tracks: t2's stays
    confirmed; with ``find`` it is the unfiltered NCC's own peak, so where the median finds the same peak the pixel is
    the default's (the same NCC surface refined from the same integer peak); the filtered pixel is within the 4 mm
    the docs score tracks by (measured: 1.90 mm against the default's 1.67 mm, OpenCV 5.0). t1's track finds no
    feature model either way (the option only changes the NCC of a candidate)."""
    ft = load("first_track_rerun")
    out = tmp_path / "rows.jsonl"
    assert ft.main(["run", str(camp), str(out), 'm3={"params": {"ncc_median_prev_px": 3, "ncc_place_flow": []}}',
                    'find={"params": {"ncc_median_prev_px": 3, "ncc_median_find": true, "ncc_place_flow": []}}']) == 0
    assert json.loads(capsys.readouterr().err)["moved"] == 0
    rows = {r["target"]: r for r in map(json.loads, out.read_text().splitlines())}
    t2 = rows["t2"]
    assert t2["default"]["status"] == t2["m3"]["status"] == t2["find"]["status"] == "confirmed"
    assert t2["find"]["uv"] == pytest.approx(t2["default"]["uv"], abs=1e-6)
    assert float(np.hypot(*t2["m3"]["err_mm"])) <= 4.0
    assert rows["t1"]["m3"]["status"] == rows["t1"]["find"]["status"] == "failed"


def test_chains_scored_again_by_closure_models(camp):
    """fit_closure_trust.py chains: the model the chains ran with gives every recorded p and GO back (so its figures
    are the campaign's own); another model is scored on the same chains; a first model that is not the chains' own
    is refused."""
    import dataclasses

    from scipctl.io.closure_trust_model import load_packaged_closure_trust_model

    fct = load("fit_closure_trust")
    model = load_packaged_closure_trust_model()
    recs = [json.loads(x)["record"] for x in (camp / "records" / "paper-s1-straight.jsonl").read_text().splitlines()[1:]]
    out = fct.chain_scores([str(camp)], {"packaged": model})
    m = out["models"]["packaged"]
    assert out["chains"] == 2 and m["chain_go"] == sum(r["go"] for r in recs)
    finals = [r["steps"][-1] for r in recs]
    y = [f["error_px"] is not None and f["error_px"] <= 4.0 for f in finals]
    assert out["within"] == sum(y)
    assert m["brier"] == pytest.approx(np.mean([((f["p_success"] or 0.0) - w) ** 2 for f, w in zip(finals, y)]))
    never = dataclasses.replace(model, go_min_p=1.0)  # no closure GO
    both = fct.chain_scores([str(camp)], {"packaged": model, "never": never})
    assert both["models"]["never"]["brier"] == m["brier"] and both["models"]["never"]["chain_go_within"] <= m["chain_go"]
    adopted = [f for f in finals if f["extra"].get("answer") == "closure"]
    if adopted:  # a first model that is not the chains' own
        with pytest.raises(ValueError, match="not the model the chains ran with"):
            fct.chain_scores([str(camp)], {"other": dataclasses.replace(model, intercept=model.intercept + 1.0)})


def test_chains_scored_again_keep_the_drives_rule_they_ran_with(camp):
    """fit_closure_trust.py chains applies the chain's drives rule: with a closure model whose GO threshold is 1e-9
    (every adopted closure with point stereo GO by its p), the fixture's chains, whose closures are NO-GO, are
    what that model gives under ``closure_go_max_drives`` 0 (every reference is at least one drive away), so they
    are scored; under the default rule (2 drives) the same model makes a closure GO that the records say is not,
    and the chains are refused as not the model's."""
    import dataclasses

    from scipctl.io.closure_trust_model import load_packaged_closure_trust_model

    fct = load("fit_closure_trust")
    always = dataclasses.replace(load_packaged_closure_trust_model(), go_min_p=1e-9)
    finals = [json.loads(x)["record"]["steps"][-1]
              for x in (camp / "records" / "paper-s1-straight.jsonl").read_text().splitlines()[1:]]
    adopted = [f for f in finals if f["extra"].get("answer") == "closure" and f["ok"]]
    assert adopted and not any(f["go"] for f in adopted)  # the bundled sol: confirmed closures, none GO
    out = fct.chain_scores([str(camp)], {"always": always}, max_drives=0)
    assert out["models"]["always"]["chain_go"] == 0
    with pytest.raises(ValueError, match="not the model the chains ran with"):
        fct.chain_scores([str(camp)], {"always": always})


def _step_model_file(tmp_path, **change):
    """The packaged step model's file with ``change`` applied to its fields, in ``tmp_path``."""
    d = json.loads((ROOT / "scipctl/data/step_trust_model.json").read_text())
    d.update(change)
    path = tmp_path / "step_model.json"
    path.write_text(json.dumps(d))
    return path


def test_chains_scored_again_by_another_step_model(camp, tmp_path, capsys):
    """docs/scripts/chain_trust_rescore.py: the model the chains ran with gives every step's p and GO and the verdict
    back; a model that is more confident raises every tracking step's p, the hazcam handoff's (scip's times its
    input's) and the closure's through its reference's p."""
    rs = load("chain_trust_rescore")
    same = tmp_path / "same.jsonl"
    model = ROOT / "scipctl/data/step_trust_model.json"
    assert rs.main(["run", str(camp), "-o", str(same), "--step-model", str(model)]) == 0
    assert json.loads(capsys.readouterr().err) == {"chains": 2, "reproduced": 2, "moved": 0}
    rows = {r["target"]: r for r in map(json.loads, same.read_text().splitlines())}
    assert all(r["new"] == r["recorded"] for r in rows.values())
    s = rs.score(list(rows.values()))
    assert s["all"]["new"] == s["all"]["recorded"] and s["all"]["recorded"]["chains"] == 2

    sure = tmp_path / "sure.jsonl"
    d = json.loads(model.read_text())
    bolder = _step_model_file(tmp_path, intercept=d["intercept"] + 3.0)
    assert rs.main(["run", str(camp), "-o", str(sure), "--step-model", str(bolder)]) == 0
    for r in map(json.loads, sure.read_text().splitlines()):
        kinds, old, new = r["kinds"], r["recorded"]["steps_p"], r["new"]["steps_p"]
        tracking = [i for i, k in enumerate(kinds) if not k.startswith("hazcam") and not k.endswith("designate")]
        assert tracking and all(new[i] > old[i] for i in tracking if r["steps_answered"][i])
        assert new[0] == old[0]  # the designation's p is its own model's
        fin = max(i for i, k in enumerate(kinds) if k.startswith("hazcam"))
        assert r["new"]["final_p"] is not None and r["new"]["final_p"] > r["recorded"]["final_p"]
        assert new[fin] == r["new"]["final_p"]


def test_chains_scored_again_with_another_closure_model(camp, tmp_path, capsys):
    """chain_trust_rescore.py run --closure-model: the packaged closure model named as a file gives the recorded arm
    back in the new arm; a bolder one raises only the adopted closures' final p (the recorded arm is unmoved)."""
    rs = load("chain_trust_rescore")
    step = ROOT / "scipctl/data/step_trust_model.json"
    closure = ROOT / "scipctl/data/closure_trust_model.json"
    same = tmp_path / "same.jsonl"
    assert rs.main(["run", str(camp), "-o", str(same), "--step-model", str(step), "--closure-model", str(closure)]) == 0
    assert json.loads(capsys.readouterr().err)["moved"] == 0
    rows = list(map(json.loads, same.read_text().splitlines()))
    assert rows and all(r["new"] == r["recorded"] for r in rows)
    d = json.loads(closure.read_text())
    d["intercept"] += 3.0
    bolder = tmp_path / "bolder_closure.json"
    bolder.write_text(json.dumps(d))
    out = tmp_path / "bold.jsonl"
    assert rs.main(["run", str(camp), "-o", str(out), "--step-model", str(step), "--closure-model", str(bolder)]) == 0
    closures = 0
    for r, r0 in zip(map(json.loads, out.read_text().splitlines()), rows):
        assert r["recorded"] == r0["recorded"] and r["new"]["steps_p"][:-1] == r0["new"]["steps_p"][:-1]
        if r["new"]["final_p"] != r0["new"]["final_p"]:
            assert r["new"]["final_p"] > r0["new"]["final_p"]
            closures += 1
    assert closures >= 1  # the fixture has chains that answer by their closures


def test_rescored_chains_are_scored_by_family_and_from_several_files(camp, tmp_path, capsys):
    """chain_trust_rescore.py score --by family: one group per scene family whose chains and successes add up to the
    whole; rows from several files are scored together; any other grouping is refused."""
    rs = load("chain_trust_rescore")
    rows_path = tmp_path / "rows.jsonl"
    assert rs.main(["run", str(camp), "-o", str(rows_path), "--step-model",
                    str(ROOT / "scipctl/data/step_trust_model.json")]) == 0
    capsys.readouterr()
    rows = list(map(json.loads, rows_path.read_text().splitlines()))
    a, b = (dict(r, family=fam) for r, fam in zip(rows, ("sand-sheet", "low-sun")))
    (tmp_path / "a.jsonl").write_text(json.dumps(a) + "\n")
    (tmp_path / "b.jsonl").write_text(json.dumps(b) + "\n")
    s = rs.score([a, b], by="family")
    assert sorted(s) == ["all", "low-sun", "sand-sheet"]
    for key in ("chains", "within_4px", "misses", "chain_go"):
        assert s["low-sun"]["new"][key] + s["sand-sheet"]["new"][key] == s["all"]["new"][key]
    assert s["all"]["new"] == rs.score(rows)["all"]["new"]  # the grouping moves no figure of the whole
    assert rs.main(["score", str(tmp_path / "a.jsonl"), str(tmp_path / "b.jsonl"), "--by", "family", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(s))
    with pytest.raises(ValueError):
        rs.score(rows, by="downlink")


def test_a_row_without_the_grouping_field_is_refused_with_exit_2(tmp_path, capsys):
    """chain_trust_rescore.py score --by family on a row that has no family: one line naming the file, exit 2."""
    rows = tmp_path / "rows.jsonl"
    rows.write_text(json.dumps({"campaign": "c", "target": "t1", "final_px": 1.0}) + "\n")
    with pytest.raises(SystemExit) as e:
        load("chain_trust_rescore").main(["score", str(rows), "--by", "family"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("chain_trust_rescore.py: error:") and str(rows) in err and "'family'" in err


def test_the_designation_again_gives_the_chains_step_0_back(camp, tmp_path, capsys):
    """Today's chains carry designate's trust on step 0: the script's designate gives it back, and the verdict
    with it is the recorded one. A record made before the designation was scored (its trust stripped) is taken as
    given before and re-judged after: the same verdict as today's chain."""
    di = load("designation_in_chains")
    out = tmp_path / "rows.jsonl"
    assert di.main(["run", str(camp), str(out)]) == 0
    assert json.loads(capsys.readouterr().err) == {"chains": 2, "reproduced": 2, "moved": 0}
    rows = {r["target"]: r for r in map(json.loads, out.read_text().splitlines())}
    recs = {json.loads(x)["record"]["target"]: json.loads(x)["record"]
            for x in (camp / "records" / "paper-s1-straight.jsonl").read_text().splitlines()[1:]}
    for tid, r in rows.items():
        s0 = recs[tid]["steps"][0]
        assert (r["p_ok"], r["go"]) == (s0["p_success"], s0["go"]) and r["recorded"] == s0["extra"]["designation"]
        assert r["before"] == r["after"] and r["after"]["go"] == recs[tid]["go"]
    s = di.score(list(rows.values()))
    assert s["chains"] == 2 and s["designation_nogo"] == sum(not r["go"] for r in rows.values())
    assert s["chain_go_before"] == s["chain_go_after"]
    # the same chains as an older campaign wrote them: no designation trust on step 0
    old = tmp_path / "old"
    (old / "records").mkdir(parents=True)
    lines = (camp / "records" / "paper-s1-straight.jsonl").read_text().splitlines()
    stripped = [lines[0]]
    for x in lines[1:]:
        rec = json.loads(x)
        st0 = rec["record"]["steps"][0]
        st0["extra"].pop("designation")
        st0["p_success"], st0["go"], st0["advice"] = None, True, None
        stripped.append(json.dumps(rec))
    (old / "records" / "paper-s1-straight.jsonl").write_text("\n".join(stripped) + "\n")
    out2 = tmp_path / "rows2.jsonl"
    assert di.main(["run", str(old), str(out2)]) == 0
    assert json.loads(capsys.readouterr().err) == {"chains": 2, "reproduced": 0, "moved": 0}
    for r in map(json.loads, out2.read_text().splitlines()):
        assert r["recorded"] is None and r["after"] == rows[r["target"]]["after"]


@pytest.mark.parametrize("script, args", [
    ("closure_references", ["run", "{tmp}", "{tmp}/o.jsonl"]),
    ("first_track_rerun", ["run", "{tmp}", "{tmp}/o.jsonl"]),
    ("first_track_rerun", ["run", "{camp}", "{tmp}/o.jsonl", 'x={"half": 20, "other": 1}']),
    ("first_track_rerun", ["run", "{camp}", "{tmp}/o.jsonl", 'x={"params": {"feature_median_px": 2}}']),
    ("closure_references", ["score", "{tmp}/missing.jsonl"]),
    ("designation_in_chains", ["run", "{tmp}", "{tmp}/o.jsonl"]),
    ("designation_in_chains", ["score", "{tmp}/missing.jsonl"]),
    ("chain_trust_rescore", ["run", "{tmp}", "-o", "{tmp}/o.jsonl", "--step-model", "scipctl/data/step_trust_model.json"]),
    ("chain_trust_rescore", ["run", "{camp}", "-o", "{tmp}/o.jsonl", "--step-model", "{tmp}/missing.json"]),
    ("chain_trust_rescore", ["score", "{tmp}/missing.jsonl"]),
    ("chain_trust_rescore", ["run", "{camp}", "-o", "{tmp}/o.jsonl", "--step-model", "scipctl/data/step_trust_model.json",
                             "--closure-model", "{tmp}/missing.json"]),
    ("chain_trust_rescore", ["run", "{camp}", "-o", "{tmp}/o.jsonl", "--step-model", "{root}/pyproject.toml"]),  # not a model
    ("chain_trust_rescore", ["run", "{camp}", "-o", "{tmp}/o.jsonl", "--step-model", "scipctl/data/step_trust_model.json",
                             "--closure-model", "{root}/scipctl/data/step_trust_model.json"]),  # the other kind
])
def test_bad_input_is_refused_with_exit_2_and_nothing_written(script, args, camp, tmp_path, capsys):
    argv = [a.replace("{tmp}", str(tmp_path)).replace("{camp}", str(camp)).replace("{root}", str(ROOT)) for a in args]
    with pytest.raises(SystemExit) as e:
        load(script).main(argv)
    assert e.value.code == 2
    assert not (tmp_path / "o.jsonl").exists()
    err = capsys.readouterr().err.strip().splitlines()[-1]  # argparse: the usage, then the one line that says why
    assert err.startswith(f"{script}.py: error:")
