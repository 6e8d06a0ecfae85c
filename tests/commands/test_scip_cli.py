"""`scipctl simulate-handoff` with scip, the default: p_success and go in every record, exit code 1 on NO-GO;
`scipctl fit-trust` reproduces its model file from the same table."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.core.handoff.trust_model import LogisticFit, TrustModel
from scipctl.io.trust_model import trust_model_json
from tests.pipeline.trust_table import small_table, write_table

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
runner = CliRunner()


def _constant_model(tmp_path, logit: float) -> Path:
    """A trust model file giving every candidate the probability sigmoid(logit), GO at 0.5."""
    m = TrustModel({}, [], [], [], [LogisticFit(r, [], logit, 0.5) for r in (1.0, 8.0)])
    p = tmp_path / f"model{logit:+g}.json"
    p.write_text(trust_model_json(m))
    return p


def test_default_is_scip_with_go_and_exit_0(sol, tmp_path):
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--target", "t1", "--json",
                            "--trust-model", str(_constant_model(tmp_path, 6.0))])
    assert r.exit_code == 0, r.stderr
    recs = json.loads(r.stdout)["results"]
    assert [x["method"] for x in recs] == ["scip"]
    x = recs[0]
    assert x["go"] is True and 0.99 < x["p_success"] < 1 and x["navcam"] in ("near", "far", "both")
    assert x["predicted_uv"] is not None and x["diagnostics"]["candidates"]


def test_no_go_exits_1_with_the_json_still_on_stdout(sol, tmp_path):
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--target", "t1", "--methods", "all", "--json",
                            "--trust-model", str(_constant_model(tmp_path, -6.0))])
    assert r.exit_code == 1, r.stderr
    assert "NO-GO" in r.stderr
    recs = json.loads(r.stdout)["results"]
    scip = [x for x in recs if x["method"] == "scip"]
    assert len(scip) == 1 and scip[0]["go"] is False and scip[0]["p_success"] < 0.01
    others = [x for x in recs if x["method"] != "scip"]
    assert {x["method"] for x in others} >= {"pure-kinematic", "mesh-registration", "consensus"}
    for x in others:
        if x["method"] == "consensus" or x["predicted_uv"] is None:
            assert x["p_success"] is None and x["go"] is None  # not a candidate of scip: not scored
        else:
            assert x["p_success"] == pytest.approx(scip[0]["p_success"]) and x["go"] is False


def test_fit_trust_reproduces_its_model_file(tmp_path):
    table = tmp_path / "table.jsonl"
    write_table(table, small_table(n_targets_per_family=12))
    outs = []
    for name in ("a.json", "b.json"):
        r = runner.invoke(app, ["fit-trust", str(table), "-o", str(tmp_path / name), "--json"])
        assert r.exit_code == 0, r.stderr
        outs.append((tmp_path / name).read_bytes())
    assert outs[0] == outs[1]
    doc = json.loads(outs[0])
    assert doc["provenance"]["inputs"]["table0"]["sha256"] and doc["provenance"]["training_families"]
    assert "time_utc" not in doc["provenance"]  # same table, same bytes


def test_fit_trust_bad_table_is_exit_2(tmp_path):
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"family": "x"}\n')
    r = runner.invoke(app, ["fit-trust", str(bad), "-o", str(tmp_path / "m.json")])
    assert r.exit_code == 2 and "evidence row" in r.stderr and not (tmp_path / "m.json").exists()


def test_packaged_model_is_reproduced_by_its_command(tmp_path, monkeypatch):
    """Issue #14 item 6: the command in the packaged model's provenance (`scipctl fit-trust` on the five tables of
    tests/data/trust/, `-o scipctl/data/trust_model.json`) makes the packaged file again: run from the repository root
    with the same arguments, only the output path differs, and it is not recorded in the fit."""
    packaged = ROOT / "scipctl/data/trust_model.json"
    want = json.loads(packaged.read_text())
    cmd = want["provenance"]["command"].split()
    assert cmd[:2] == ["scipctl", "fit-trust"] and cmd[-2] == "-o"
    monkeypatch.chdir(ROOT)
    out = tmp_path / "trust_model.json"
    r = runner.invoke(app, cmd[1:-1] + [str(out)])
    assert r.exit_code == 0, r.stderr
    got = json.loads(out.read_text())
    got["provenance"]["command"] = want["provenance"]["command"]  # argv here is pytest's
    assert got == want
    assert trust_model_json(TrustModel.from_dict(got)) == packaged.read_text()  # and so the same bytes


def test_family_of_a_sim_record():
    from scipctl.commands.trust import family_of_record
    from scipctl.sim.families import FAMILIES

    assert family_of_record({"family": "err2", "scenario": "paper"}) == "err2"  # docs/scripts/trust_render.py
    assert family_of_record({"family": FAMILIES["low-sun"].to_dict(), "scenario": "paper"}) == "low-sun"  # synth --family
    assert family_of_record({"scenario": "paper"}) == "paper" and family_of_record({}) == "unknown"
