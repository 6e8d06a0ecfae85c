"""docs/scripts/chain_pairs.py: chains of two campaigns paired by (family, file name, target), counted and compared."""

import json

import pytest

from tests import doc_scripts


def _step(camera, kind, error_px, ok=True, p=None, final=False):
    return {"camera": camera, "kind": kind, "error_px": error_px, "ok": ok, "p_success": p,
            "tracked_uv": None if error_px is None else [1.0, 2.0], "extra": {"final": True} if final else {}}


def _chain(target, first_px, final_px, go=False, p=0.5):
    steps = [_step("pancam", "designate", 0.0), _step("pancam", "track", first_px, ok=first_px < 4)]
    if final_px is not None:  # a chain that stopped before the hazcam stop has no final step
        steps.append(_step("hazcam", "handoff", final_px, p=p, final=True))
    return {"target": target, "steps": steps, "go": go}


def _campaign(root, folder, family, chains):
    rec = root / "records"
    rec.mkdir(parents=True, exist_ok=True)
    head = {"kind": "downlink", "status": "ok", "family": family, "downlink": "paper-s1-straight.mcap",
            "job": {"path": f"/somewhere/{folder}/paper-s1-straight.mcap"}}
    lines = [head] + [{"kind": "chain", "record": c} for c in chains]
    (rec / f"{family}.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))


def test_pairs_counts_and_won_lost(tmp_path, capsys):
    cp = doc_scripts.load("chain_pairs")
    ctrl, var = tmp_path / "ctrl", tmp_path / "var"
    _campaign(ctrl, "control", "default", [_chain("t1", 1.0, 1.0, go=True, p=0.96), _chain("t2", 1.0, 9.0, p=0.2),
                                           _chain("t3", 30.0, None)])
    _campaign(var, "sun", "default", [_chain("t1", 20.0, 12.0, p=0.4), _chain("t2", 1.0, 2.0, p=0.8),
                                      _chain("t3", 30.0, None)])
    assert cp.main([str(ctrl), str(var), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)["variants"][0]
    assert rep["paired"] == 3 and rep["only_control"] == rep["only_variant"] == 0
    c, v = rep["control"], rep["variant_stats"]
    assert (c["within_4px"], c["chain_go"], c["go_misses"], c["misses"], c["misses_nogo"]) == (1, 1, 0, 2, 2)
    assert (c["first_track_within_4px"], c["first_track_flagged"], c["answered"]) == (2, 1, 2)
    assert c["final_p_brier"] == pytest.approx(((0.96 - 1) ** 2 + 0.2 ** 2) / 2)
    assert (v["within_4px"], v["first_track_within_4px"], v["first_track_flagged"]) == (1, 1, 2)
    assert rep["won"] == ["default/paper-s1-straight.mcap/t2"] and rep["lost"] == ["default/paper-s1-straight.mcap/t1"]


def test_a_folder_without_records_is_refused_with_exit_2(tmp_path):
    cp = doc_scripts.load("chain_pairs")
    with pytest.raises(SystemExit) as ex:
        cp.main([str(tmp_path), str(tmp_path)])
    assert ex.value.code == 2


def test_two_downlinks_of_one_family_and_name_in_one_campaign_are_refused(tmp_path, capsys):
    """Two populations in one campaign give two `default` downlinks named paper-s1-straight.mcap: their chains
    cannot be paired by (family, file name, target), so the script says so in one line and exits 2 instead of
    silently keeping one of them."""
    cp = doc_scripts.load("chain_pairs")
    ctrl, var = tmp_path / "ctrl", tmp_path / "var"
    _campaign(ctrl, "pop1/default-1", "default", [_chain("t1", 1.0, 1.0)])
    head = {"kind": "downlink", "status": "ok", "family": "default", "downlink": "paper-s1-straight.mcap",
            "job": {"path": "/somewhere/pop2/default-2/paper-s1-straight.mcap"}}
    (ctrl / "records" / "second.jsonl").write_text(json.dumps(head) + "\n" + json.dumps(
        {"kind": "chain", "record": _chain("t1", 1.0, 9.0)}) + "\n")
    _campaign(var, "pop1/default-1", "default", [_chain("t1", 1.0, 1.0)])
    assert cp.main([str(ctrl), str(var)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "two default downlinks named paper-s1-straight.mcap" in err[0]
