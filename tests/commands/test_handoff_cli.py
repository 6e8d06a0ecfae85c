"""`scipctl simulate-handoff` from the command line: JSON contract, Table 1, bad input."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from scipctl.cli import app

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
runner = CliRunner()


def test_json_results_carry_the_contract_fields(sol):
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--methods", "pure-kinematic,pure-geometric-near", "--json"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    recs = doc["results"]
    # pure-kinematic near+far and pure-geometric near only, for the 3 marked targets
    assert {(x["method"], x["navcam"]) for x in recs} == {("pure-kinematic", "near"), ("pure-kinematic", "far"),
                                                          ("pure-geometric", "near")}
    assert len(recs) == 9
    for x in recs:
        for k in ("downlink", "target", "method", "navcam", "predicted_uv", "truth_uv", "error_px", "success"):
            assert k in x
        if x["predicted_uv"] is not None and x["truth_uv"] is not None:
            dx = x["predicted_uv"][0] - x["truth_uv"][0]
            dy = x["predicted_uv"][1] - x["truth_uv"][1]
            assert abs((dx * dx + dy * dy) ** 0.5 - x["error_px"]) < 1e-9
            assert x["success"] == (x["error_px"] <= 4.0)
    assert {row["method"] for row in doc["table1"]} == {"pure-kinematic", "pure-geometric"}
    assert doc["provenance"]["inputs"]["downlink0"]["sha256"]
    # the Table-1 rendering goes to stderr, beside the paper's figures
    assert "Table 1" in r.stderr and "13±3" in r.stderr
    saved = json.loads((sol.parent / (sol.name + ".scipctl") / "handoff.json").read_text())
    assert len(saved["results"]) == 9
    # the stereo self-calibration (the default) of the pairs the handoff reads, navcam and hazcam: recorded
    fits = saved["provenance"]["stereo_selfcal"]
    assert fits == doc["downlinks"][0]["stereo_selfcal"]
    assert sorted(f["camera"] for f in fits) == ["hazcam", "navcam", "navcam", "navcam"]
    # and the answers are those of the downlink with every pair self-calibrated (as campaign and --chain do): the
    # handoff reads no other pair, and a pair's fit reads that pair alone
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.handoff import build_setup, marked_targets, run_targets
    from scipctl.pipeline.stereo_selfcal import self_calibrate_downlink

    dl, _ = self_calibrate_downlink(read_downlink(sol))
    setup = build_setup(dl, shared=True)
    want = run_targets(dl, setup, marked_targets(dl, setup), methods=["pure-kinematic", "pure-geometric"],
                       downlink_name=sol.name, only={("pure-kinematic", "near"), ("pure-kinematic", "far"),
                                                     ("pure-geometric", "near")})
    assert [x["predicted_uv"] for x in recs] == [w.to_dict()["predicted_uv"] for w in want]


def test_from_pixel_runs_one_source_pixel(sol):
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.handoff import find_products

    dl = read_downlink(sol)
    _, near, _ = find_products(dl)
    mk = dl.targets[0].mark_in(near.product_id)
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--from", near.product_id, "--pixel", f"{mk.u},{mk.v}",
                            "--methods", "pure-kinematic", "--json"])
    assert r.exit_code == 0, r.stderr
    recs = json.loads(r.stdout)["results"]
    assert len(recs) == 1 and recs[0]["navcam"] == "near" and recs[0]["truth_uv"] is None
    assert recs[0]["predicted_uv"] is not None
    # without --json the answer is on stderr too (it showed only an empty Table 1 before)
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--from", near.product_id, "--pixel", f"{mk.u},{mk.v}",
                            "--methods", "pure-kinematic"], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.stderr
    u, v = recs[0]["predicted_uv"]
    text = " ".join(r.stderr.split())
    assert "Answers (scip, and unscored pixels)" in text and "unscored" in text and f"{u:.2f}, {v:.2f}" in text


@pytest.mark.parametrize("args,needle", [
    (["--methods", "telepathy"], "telepathy"),
    (["--methods", ""], "empty"),  # was accepted, running scip
    (["--success-px", "0"], "success_px"),
    (["--success-px", "inf", "--methods", "pure-kinematic"], "success_px"),  # was exit 3 (JSON could not hold inf)
    (["--from", "s1-straight-pan10-pancam-L", "--pixel", "10,10"], "navcam"),
    (["--pixel", "10,10"], "--from"),
    (["--from", "s1-straight-far-navcam-L", "--pixel", "10,10", "--target", "t2"], "for that pixel alone"),
    # products of the wrong camera or stop were answered (a pancam as the near navcam, the hazcam handed off to itself)
    (["--near", "s1-straight-mid-pancam-L"], "s1-straight-mid-pancam-L: camera: expected a left navcam product"),
    (["--far", "s1-straight-near-hazcam-L"], "s1-straight-near-hazcam-L: camera: expected a left navcam product"),
    (["--hazcam", "s1-straight-near-navcam-L"], "s1-straight-near-navcam-L: camera: expected a left hazcam"),
    (["--near", "s1-straight-far-navcam-L"], "s1-straight-far-navcam-L: position: the near navcam must be at"),
    (["--far", "s1-straight-near-navcam-L"], "s1-straight-near-navcam-L: position: the far navcam must be at"),
    (["--near", "s1-straight-near-navcam-R"], "eye: expected a left-eye navcam product, got right"),
    (["--target", "nope"], "nope"),
    # an empty value (`--target "$T"`, T unset) was taken as "not given": every target, or the chosen product
    (["--target", ""], "--target: target: empty"),
    (["--near", " "], "--near: near: empty"),
    (["--far", ""], "--far: far: empty"),
    (["--hazcam", ""], "--hazcam: hazcam: empty"),
    (["--from", "", "--pixel", "10,10"], "--from: from: empty"),
])
def test_bad_input_exits_2_with_one_line(sol, args, needle):
    r = runner.invoke(app, ["simulate-handoff", str(sol)] + args)
    assert r.exit_code == 2, r.output
    assert needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.parametrize("args, needle", [
    (["--from", "s1-straight-pan10-pancam-L", "--pixel", "10,10"], "navcam"),
    (["--from", "no-such-product", "--pixel", "10,10"], "no-such-product: product_id"),
    (["--from", "s1-straight-near-navcam-L", "--pixel", "5000,10"], "outside the image"),
    (["--from", "s1-straight-near-navcam-L", "--pixel", "nan,3"], "pixel"),
    (["--near", "s1-straight-mid-pancam-L"], "camera: expected a left navcam product"),
    (["--hazcam", "s1-straight-near-navcam-L"], "camera: expected a left hazcam"),
    (["--far", "s1-straight-near-navcam-L"], "position: the far navcam must be at"),
    (["--target", "nope"], "nope: target"),
    (["--target", "nope", "--chain"], "nope: target"),
])
def test_a_bad_product_or_target_option_is_refused_before_any_stereo_work(sol, monkeypatch, args, needle):
    """Every source's --from/--pixel, --near/--far/--hazcam and --target are checked before the self-calibration
    fits a pair (seconds of work)."""
    import scipctl.commands.selfcal as selfcal

    def refuse(*_a, **_k):
        raise AssertionError("the stereo self-calibration ran before the options were checked")

    monkeypatch.setattr(selfcal, "self_calibrate", refuse)
    r = runner.invoke(app, ["simulate-handoff", str(sol)] + args)
    assert r.exit_code == 2 and needle in r.stderr, r.output
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_missing_and_corrupt_inputs_exit_2(tmp_path):
    r = runner.invoke(app, ["simulate-handoff", str(tmp_path / "absent.mcap")])
    assert r.exit_code == 2
    bad = tmp_path / "half.mcap"
    bad.write_bytes(SAMPLE.read_bytes()[:100000])
    r = runner.invoke(app, ["simulate-handoff", str(bad)])
    assert r.exit_code == 2 and "half.mcap" in r.stderr


def test_chain_option_reports_every_step_against_the_marks(sol):
    """--chain: the whole chain from the pancam designation, in the JSON (per step: the mark, the error, the
    trust flag, p_success and GO; per chain its GO and advice) and as a table on stderr with a trust column. A
    chain that ends NO-GO is the command's "no" (exit 1), its JSON written all the same."""
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--target", "t2", "--methods", "pure-kinematic-near",
                            "--chain", "--json"])
    doc = json.loads(r.stdout)
    (ch,) = doc["chains"]
    assert r.exit_code == (0 if ch["go"] else 1), r.stderr
    if not ch["go"]:
        assert "chain: NO-GO for 1 of 1 chains" in r.stderr and ch["advice"] and ch["why"]
    assert ch["target"] == "t2"
    steps = ch["steps"]
    assert all(isinstance(s["go"], bool) and "p_success" in s for s in steps)
    assert [s["kind"] for s in steps][0] == "designate" and steps[0]["camera"] == "pancam"
    assert steps[-1]["camera"] == "hazcam"
    assert {s["camera"] for s in steps} == {"pancam", "navcam", "hazcam"}
    for s in steps:
        assert isinstance(s["ok"], bool)
        if s["tracked_uv"] is not None and s["mark_uv"] is not None:
            du, dv = (s["tracked_uv"][i] - s["mark_uv"][i] for i in (0, 1))
            assert abs((du * du + dv * dv) ** 0.5 - s["error_px"]) < 1e-9
    # the designation is the mark itself
    assert steps[0]["error_px"] == 0.0
    assert "tracking chain" in r.stderr and "trust" in r.stderr
    if steps[-1]["extra"].get("answer") == "closure":  # the final answer's origin is in its trust column
        assert "closure" in r.stderr


def test_a_narrower_run_says_it_replaces_earlier_results_and_hashes_its_trust_model(tmp_path):
    """handoff.json holds the latest run only (sequence chooses its handoff method from it): a run that drops
    earlier results says so; a --trust-model file is among the hashed inputs (p_success and go depend on it)."""
    sol = tmp_path / SAMPLE.name
    sol.write_bytes(SAMPLE.read_bytes())
    assert runner.invoke(app, ["simulate-handoff", str(sol), "--methods", "pure-kinematic"]).exit_code == 0
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--methods", "pure-kinematic", "--target", "t1"])
    assert r.exit_code == 0, r.stderr
    assert "handoff.json replaced: 4 earlier results not in this run (methods pure-kinematic; targets t2, t3)" in r.stderr
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--methods", "pure-kinematic", "--target", "t1"])
    assert "handoff.json replaced" not in r.stderr  # the same results again: nothing dropped
    model = ROOT / "scipctl/data/trust_model.json"
    r = runner.invoke(app, ["simulate-handoff", str(sol), "--target", "t1", "--trust-model", str(model), "--json"])
    assert r.exit_code in (0, 1), r.stderr
    import hashlib

    sha = hashlib.sha256(model.read_bytes()).hexdigest()
    assert json.loads(r.stdout)["provenance"]["inputs"]["trust_model"] == {"path": str(model), "sha256": sha}
    saved = json.loads((tmp_path / (SAMPLE.name + ".scipctl") / "handoff.json").read_text())
    assert saved["provenance"]["inputs"]["trust_model"]["sha256"] == sha


def test_a_bad_option_for_a_later_source_leaves_every_source_as_it_was(tmp_path):
    # --near names a product of the first downlink only: the second stops with exit 2. The first's handoff.json
    # used to be replaced before that (README: exit 2 leaves nothing half-written)
    a, b = tmp_path / "a" / SAMPLE.name, tmp_path / "b" / "paper-s1-arc.mcap"
    a.parent.mkdir(), b.parent.mkdir()
    a.write_bytes(SAMPLE.read_bytes())
    b.write_bytes((SAMPLE.parent / "paper-s1-arc.mcap").read_bytes())
    side = Path(str(a) + ".scipctl")
    side.mkdir()
    (side / "handoff.json").write_text('{"earlier": true}')
    r = runner.invoke(app, ["simulate-handoff", str(a), str(b), "--methods", "pure-kinematic",
                            "--near", "s1-straight-near-navcam-L"])
    assert r.exit_code == 2, r.stderr
    assert r.stderr.strip().splitlines()[-1].startswith("scipctl: error: ") and "s1-straight-near-navcam-L" in r.stderr
    assert (side / "handoff.json").read_text() == '{"earlier": true}'
    assert not Path(str(b) + ".scipctl", "handoff.json").exists()


def test_a_downlink_named_twice_is_scored_once(sol):
    # `simulate-handoff a.mcap ./a.mcap` (or a glob that also matches a named file) used to score every target
    # twice: Table 1's n doubled and its statistics weighted that downlink twice; campaign uses each once
    again = Path(sol.parent, ".", sol.name)
    r = runner.invoke(app, ["simulate-handoff", str(sol), str(again), "--methods", "pure-kinematic-near", "--json"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    assert len(doc["results"]) == 3 and len(doc["downlinks"]) == 1
    assert [row["cases"] for row in doc["table1"]] == [3]
    assert "given again: used once" in r.stderr


def test_two_downlinks_of_one_name_are_told_apart(tmp_path):
    # sol42/ws and sol43/ws: every result used to say downlink "ws" for both (a script could not tell which
    # answer is whose, a NO-GO line named "ws:t1") and the table counted their 6 targets as 3
    a, b = tmp_path / "sol42" / SAMPLE.name, tmp_path / "sol43" / SAMPLE.name
    for p in (a, b):
        p.parent.mkdir()
        p.write_bytes(SAMPLE.read_bytes())
    r = runner.invoke(app, ["simulate-handoff", str(a), str(b), "--methods", "pure-kinematic-near", "--json"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    assert {x["downlink"] for x in doc["results"]} == {str(a), str(b)}
    assert [d["downlink"] for d in doc["downlinks"]] == [str(a), str(b)]
    assert "(6 targets)" in r.stderr
