"""``scipctl sequence`` through the CLI on a synthetic downlink (a 45-degree slab target, real dense stereo)."""

import json
import shutil
from dataclasses import replace

import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import read_downlink, write_downlink
from tests.pipeline import scene as S

runner = CliRunner()


@pytest.fixture(scope="module")
def slab_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("seq") / "sol7"
    _, dl = S.cached("slab")
    write_downlink(dl, d, container="dir")
    return d


def test_seqn_sequence_is_written_and_byte_identical_on_a_rerun(tmp_path, slab_dir):
    out = tmp_path / "t_slab.seqn"
    args = ["sequence", str(slab_dir), "--target", "t_slab", "-o", str(out)]
    r1 = runner.invoke(app, args)
    assert r1.exit_code == 0, r1.stderr
    first = out.read_bytes()
    r2 = runner.invoke(app, args)
    assert r2.exit_code == 0, r2.stderr
    assert out.read_bytes() == first
    assert r1.stdout == ""  # the sequence went to the file
    text = first.decode()
    assert '@ID "scip_t_slab_sol7"' in text and "NOTIONAL" in text
    lines = text.splitlines()
    meta = {ln.split(" ", 2)[1].strip('"'): json.loads(ln.split(" ", 2)[2]) for ln in lines if ln.startswith("@METADATA")}
    sha = read_downlink(slab_dir).source_sha256
    assert meta["provenance"]["inputs"]["downlink"]["sha256"] == sha
    assert meta["provenance"]["tool"] == "scipctl" and "time_utc" not in meta["provenance"]
    assert "cwd" not in meta["provenance"]  # same inputs, same bytes, from any folder
    assert len(meta["provenance"]["inputs"]["stereo_selfcal"]["sha256"]) == 64  # today's pairs' fits, hashed
    assert all(r["ok"] for r in meta["rules"])
    stems = [ln.split()[1] for ln in lines if ln.startswith("R")]
    assert stems[-2:] == ["ARM_PLACE_AT_TARGET", "SCIP_END"] and "TRK_HANDOFF_SCIP" in stems
    scip = next(ln.split() for ln in lines if " TRK_HANDOFF_SCIP " in ln)
    from scipctl.io.trust_model import load_packaged_trust_model

    # navcam BOTH, success_px 4, GO at the packaged trust model's threshold for 4 px (what the chain's scip uses)
    assert scip[2:5] == ["BOTH", "4.0", f"{load_packaged_trust_model().go_threshold(4.0):g}"]
    assert meta["handoff"]["primary"] == "scip"


def test_handoff_best_single_commands_a_paper_method_and_a_bad_choice_is_exit_2(slab_dir):
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--handoff", "best-single"])
    assert r.exit_code == 0, r.stderr
    assert " TRK_HANDOFF_NAVCAM_HAZCAM REFINED_KINEMATIC PURE_GEOMETRIC NEAR " in r.stdout  # the paper's Table 1
    assert "TRK_HANDOFF_SCIP" not in r.stdout
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--handoff", "consensus"])
    assert r.exit_code == 2 and "--handoff" in r.stderr and r.stderr.count("\n") == 1


def test_json_format_and_summary_on_stdout(slab_dir):
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--format", "json", "--json"])
    assert r.exit_code == 0, r.stderr
    summary = json.loads(r.stdout)  # one JSON document: the rule summary, carrying the sequence
    assert summary["ok"] and summary["designated_now"]  # t_slab is only marked: designated on the fly
    assert {c["rule"] for c in summary["rules"]} >= {"max-drive-distance", "prediction-confidence", "final-tilt"}
    doc = json.loads(summary["sequence"])
    assert doc["format"] == "scipctl-sequence/1" and doc["target"]["designated_from"] == "mark"
    assert len(doc["commands"]) == summary["commands"]
    # the stereo self-calibration (the default) of today's pairs only: the designation's stop
    fits = summary["provenance"]["stereo_selfcal"]
    position = {im.product_id: im.position for im in read_downlink(slab_dir).images}
    assert fits and {position[f["left"]] for f in fits} == {position[doc["target"]["product_id"]]}
    truth = S.TARGET_SLAB_SITE
    assert sum((a - b) ** 2 for a, b in zip(doc["target"]["xyz_site_m"], truth)) ** 0.5 < 0.05


def test_the_plain_text_format_says_how_it_was_made(slab_dir, tmp_path):
    out = tmp_path / "s.txt"
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--format", "text", "-o", str(out)])
    assert r.exit_code == 0, r.stderr
    text = out.read_text()
    from scipctl import __version__

    assert f"made by scipctl {__version__}: " in text
    doc = json.loads(runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--format", "json"]).stdout)
    assert f"input downlink: sha256 {doc['provenance']['inputs']['downlink']['sha256']}" in text


def test_the_summary_and_the_document_carry_the_calibrated_and_the_simulated_probability(slab_dir):
    """P(success) is the packaged planner's-route calibration of the simulated P; both are in the --json summary and
    in the sequence's prediction block, each checked by its own rule; an out-of-range --min-p-simulated is exit 2
    naming the option."""
    from scipctl.io.prediction_calibration import load_packaged_prediction_calibration

    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--format", "json", "--json"])
    assert r.exit_code == 0, r.stderr
    summary = json.loads(r.stdout)
    model = load_packaged_prediction_calibration("plan")
    assert summary["confidence"] == model.p_success(summary["p_simulated"])
    assert summary["calibration"].startswith("plan route: fitted on")
    rules = {c["rule"]: c for c in summary["rules"]}
    assert rules["prediction-confidence"]["value"] == summary["confidence"] and rules["prediction-confidence"]["limit"] == 0.5
    assert rules["simulated-risk"]["value"] == summary["p_simulated"] and rules["simulated-risk"]["limit"] == 0.7
    pred = json.loads(summary["sequence"])["prediction"]
    # the document's floats are rounded to 6 decimals (pipeline/sequence.py _round)
    assert pred["confidence"] == round(summary["confidence"], 6) and pred["p_simulated"] == round(summary["p_simulated"], 6)
    bad = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--min-p-simulated", "2"])
    assert bad.exit_code == 2 and "--min-p-simulated" in bad.stderr.strip().splitlines()[-1]


def test_a_broken_rule_means_no_sequence_and_exit_1(tmp_path, slab_dir):
    src = tmp_path / "sol7"
    shutil.copytree(slab_dir, src)
    dl = read_downlink(src)
    rec = replace(S.designation_record(dl, "t_slab"), id="t_far", xyz_site_m=(30.0, 0.0, 0.0))  # beyond the drive limit
    side = src.parent / "sol7.scipctl"
    side.mkdir()
    (side / "targets.json").write_text(json.dumps({"targets": [rec.to_dict()]}))
    out = tmp_path / "far.seqn"
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_far", "-o", str(out), "--json"])
    assert r.exit_code == 1
    assert not out.exists()
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("scipctl: error: t_far:") and "max-drive-distance" in last and "no sequence written" in last
    summary = json.loads(r.stdout)
    assert summary["ok"] is False
    assert "max-drive-distance" in {c["rule"] for c in summary["rules"] if not c["ok"]}


def test_bad_input_is_one_line_and_exit_2(tmp_path, slab_dir):
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "no_such_target"])
    assert r.exit_code == 2
    assert r.stderr.count("\n") == 1 and "no_such_target" in r.stderr and "t_slab" in r.stderr
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--format", "yaml"])
    assert r.exit_code == 2 and "--format" in r.stderr and r.stderr.count("\n") == 1
    r = runner.invoke(app, ["sequence", str(tmp_path / "missing"), "--target", "t_slab"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1


def test_a_bad_field_in_targets_json_is_exit_2_naming_the_file_and_field(tmp_path, slab_dir):
    src = tmp_path / "sol8"
    shutil.copytree(slab_dir, src)
    dl = read_downlink(src)
    rec = S.designation_record(dl, "t_slab").to_dict()
    side = src.parent / "sol8.scipctl"
    side.mkdir()
    (side / "targets.json").write_text(json.dumps({"targets": [dict(rec, id="t_bad", pixel_uv=[1.0])]}))
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_slab", "--json"])
    assert r.exit_code == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith(f"scipctl: error: {side / 'targets.json'}: targets[0].pixel_uv: target 't_bad': "
                               "expected 2 finite numbers"), r.stderr


def test_bad_pose_sigma_flag_is_exit_2():
    from typer.testing import CliRunner

    from scipctl.cli import app

    r = CliRunner().invoke(app, ["sequence", "whatever.mcap", "--target", "t1", "--sigma-position-m", "-1"])
    assert r.exit_code == 2 and "sigma" in r.stderr


def test_rules_file_and_options_decide_and_are_recorded(tmp_path, slab_dir):
    import hashlib

    rules = tmp_path / "short.yaml"
    rules.write_text("flight_rules:\n  max_drive_m: 1.0\n")
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--rules", str(rules), "--json"])
    assert r.exit_code == 1 and "max-drive-distance" in r.stderr.strip().splitlines()[-1]
    assert json.loads(r.stdout)["rules_file"]["sha256"] == hashlib.sha256(rules.read_bytes()).hexdigest()
    out = tmp_path / "t.seqn"
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--rules", str(rules),
                            "--max-drive-m", "50", "-o", str(out)])
    assert r.exit_code == 0, r.stderr
    meta = {ln.split(" ", 2)[1].strip('"'): json.loads(ln.split(" ", 2)[2])
            for ln in out.read_text().splitlines() if ln.startswith("@METADATA")}
    used = meta["rules_used"]
    assert used["file"] == str(rules) and used["sha256"] == hashlib.sha256(rules.read_bytes()).hexdigest()
    assert used["overrides"] == {"--max-drive-m": 50.0} and used["values"]["flight_rules"]["max_drive_m"] == 50.0
    assert used["values"]["flight_rules"]["min_p_success"] == 0.5  # the default file's value for keys not given
    assert used["values"]["flight_rules"]["min_p_simulated"] == 0.7
    assert meta["provenance"]["inputs"]["rules_file"]["sha256"] == used["sha256"]
    # the same through --format seqjson: valid against Aerie's SeqJSON schema, the same metadata
    import jsonschema

    from tests.pipeline.seqjson_schema import SEQJSON_SCHEMA

    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--rules", str(rules),
                            "--max-drive-m", "50", "--format", "seqjson"])
    assert r.exit_code == 0, r.stderr
    seq = json.loads(r.stdout)
    jsonschema.Draft202012Validator(SEQJSON_SCHEMA).validate(seq)
    assert seq["metadata"] == meta and [s["stem"] for s in seq["steps"]][-2:] == ["ARM_PLACE_AT_TARGET", "SCIP_END"]


def test_a_bad_rules_file_is_one_line_and_exit_2(tmp_path):
    rules = tmp_path / "bad.yaml"
    rules.write_text("flight_rules:\n  rock_keep_out: 0.1\n")
    r = runner.invoke(app, ["sequence", "whatever.mcap", "--target", "t1", "--rules", str(rules)])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1
    assert str(rules) in r.stderr and "flight_rules.rock_keep_out" in r.stderr and "unknown key" in r.stderr
    r = runner.invoke(app, ["sequence", "whatever.mcap", "--target", "t1", "--min-p-success", "2"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "--min-p-success" in r.stderr


@pytest.mark.parametrize("value", ["2001-13-01", "9" * 5000, "[" * 5000 + "]" * 5000],
                         ids=["month-13", "5000-digit-integer", "5000-deep-list"])
def test_a_rules_value_python_cannot_build_is_one_line_and_exit_2(tmp_path, value):
    """``max_drive_m: 2001-13-01`` was ``internal error (ValueError): month must be in 1..12``, exit 3."""
    rules = tmp_path / "bad.yaml"
    rules.write_text(f"flight_rules:\n  max_drive_m: {value}\n")
    r = runner.invoke(app, ["sequence", "whatever.mcap", "--target", "t1", "--rules", str(rules)])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and str(rules) in r.stderr, r.stderr[-300:]
    assert "internal error" not in r.stderr


def test_rules_not_given_are_chosen_from_the_downlinks_rover_and_a_builtin_by_name(tmp_path, slab_dir):
    from scipctl.io.provenance import sha256_file
    from scipctl.io.rules_file import BUILTIN_RULES

    out = tmp_path / "t.seqn"
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "-o", str(out), "--json"])
    assert r.exit_code == 0, r.stderr
    used = json.loads(r.stdout)["rules_file"]
    assert used["file"] == "default (scipctl/data/rules.yaml)" and "is not Mars 2020" in used["chosen_by"]
    meta = {ln.split(" ", 2)[1].strip('"'): json.loads(ln.split(" ", 2)[2])
            for ln in out.read_text().splitlines() if ln.startswith("@METADATA")}
    assert meta["rules_used"]["chosen_by"] == used["chosen_by"] and meta["rules_used"]["sha256"] == used["sha256"]
    assert r.stderr.startswith("rules: default (scipctl/data/rules.yaml) (not given;")
    # the Mars 2020 built-in by name, on this (default rover's) downlink: read, recorded with its hash
    r = runner.invoke(app, ["sequence", str(slab_dir), "--target", "t_slab", "--rules", "m2020", "--json"])
    assert r.exit_code in (0, 1), r.stderr
    used = json.loads(r.stdout)["rules_file"]
    assert used == {"file": "m2020 (scipctl/data/rules-m2020.yaml)", "sha256": sha256_file(BUILTIN_RULES["m2020"]),
                    "overrides": {}}
    arm = next(c for c in json.loads(r.stdout)["rules"] if c["rule"] == "arm-workspace")
    assert "1.80-2.78 m" in arm["message"]


def _with_targets_and_handoff(tmp_path, slab_dir, name, records=None, handoff=None):
    """A copy of the slab sol whose sidecar holds ``records`` (Designation list) and/or a ``handoff.json``."""
    src = tmp_path / name
    shutil.copytree(slab_dir, src)
    side = src.parent / f"{name}.scipctl"
    side.mkdir()
    if records is not None:
        (side / "targets.json").write_text(json.dumps({"targets": [r.to_dict() for r in records]}))
    if handoff is not None:
        (side / "handoff.json").write_text(json.dumps(handoff))
    return src, side


def test_a_designation_called_no_go_gets_no_sequence_and_exit_1(tmp_path, slab_dir):
    # designate said "saved, but re-designate before planning on it"; sequence used to uplink it anyway (exit 0)
    dl = read_downlink(slab_dir)
    rec = replace(S.designation_record(dl, "t_slab"), id="t_ng", p_ok=0.65, ok_tolerance_pct=1.0, go=False)
    src, _ = _with_targets_and_handoff(tmp_path, slab_dir, "sol9", records=[rec])
    out = tmp_path / "ng.seqn"
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_ng", "-o", str(out), "--json"])
    assert r.exit_code == 1, r.stderr
    assert not out.exists()
    summary = json.loads(r.stdout)
    bad = {c["rule"]: c for c in summary["rules"] if not c["ok"]}
    assert "designation-go" in bad and "re-designate" in bad["designation-go"]["message"]
    assert summary["provenance"]["inputs"]["downlink"]["sha256"] == dl.source_sha256  # the NO-GO answer too
    # the same designation called GO plans as before
    src2, _ = _with_targets_and_handoff(tmp_path, slab_dir, "sol10", records=[replace(rec, id="t_go", p_ok=0.97, go=True)])
    r = runner.invoke(app, ["sequence", str(src2), "--target", "t_go", "--json"])
    summary = json.loads(r.stdout)
    rule = next(c for c in summary["rules"] if c["rule"] == "designation-go")  # listed, and passed
    assert rule["ok"] and rule["value"] == 0.97 and "re-designate" not in rule["message"]
    assert summary["provenance"]["tool"] == "scipctl"


@pytest.mark.parametrize("table1, field", [
    (5, "table1"),
    ([{"method": "rm -rf", "navcam": "near", "cases": 3}], "table1[0].method"),
    ([{"method": "scip", "navcam": "any", "cases": 3, "success_rate": "high"}], "table1[0].success_rate"),
])
def test_a_malformed_table1_in_handoff_json_is_exit_2_naming_the_field(tmp_path, slab_dir, table1, field):
    # the saved Table 1 chooses the method the uplink commands: a TypeError (exit 3), or an unchecked method name
    # written into the sequence ("TRK_HANDOFF_NAVCAM_HAZCAM RM _RF"), before
    src, side = _with_targets_and_handoff(tmp_path, slab_dir, "sol11", handoff={"results": [], "table1": table1})
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_slab", "--json"])
    assert r.exit_code == 2, r.stderr
    assert r.stdout == "" and r.stderr.count("\n") == 1
    assert str(side / "handoff.json") in r.stderr and f"{field}:" in r.stderr, r.stderr


def test_the_output_may_not_be_the_input_or_one_of_its_files(tmp_path, slab_dir, sol):
    # `-o` naming the downlink replaced it with the sequence text (exit 0)
    before = sol.read_bytes()
    r = runner.invoke(app, ["sequence", str(sol), "--target", "t2", "-o", str(sol)])
    assert r.exit_code == 2 and "would overwrite the input" in r.stderr and r.stderr.count("\n") == 1
    assert sol.read_bytes() == before
    src = tmp_path / "sol12"
    shutil.copytree(slab_dir, src)
    yaml_before = (src / "downlink.yaml").read_bytes()
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_slab", "-o", str(src / "downlink.yaml")])
    assert r.exit_code == 2 and (src / "downlink.yaml").read_bytes() == yaml_before
    side = src.parent / "sol12.scipctl"
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_slab", "-o", str(side / "targets.json")])
    assert r.exit_code == 2 and not (side / "targets.json").exists()
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_slab", "-o", str(src / "t_slab.seqn")])
    assert r.exit_code == 0, r.stderr  # another file beside the downlink's is fine


def test_the_output_may_not_be_a_file_in_the_products_dir_or_the_fallback(tmp_path, slab_dir, monkeypatch):
    # with --products-dir PD the source's products live in PD/<key>/ (and a read-only raw downlink's in the
    # per-user fallback .../sidecars/<key>/): `-o` naming a file there replaced that product with the sequence text
    from scipctl.io.product_store import source_key

    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    src = tmp_path / "sol13"
    shutil.copytree(slab_dir, src)
    pd = tmp_path / "pd"
    for out in (pd / source_key(src) / "targets.json",
                tmp_path / "xdg" / "scipctl" / "sidecars" / source_key(src) / "x.seqn"):
        r = runner.invoke(app, ["sequence", str(src), "--target", "t_slab", "--products-dir", str(pd), "-o", str(out)])
        assert r.exit_code == 2 and "would overwrite the input" in r.stderr and r.stderr.count("\n") == 1, r.stderr
        assert not out.exists()
    r = runner.invoke(app, ["sequence", str(src), "--target", "t_slab", "--products-dir", str(pd),
                            "-o", str(pd / "t_slab.seqn")])
    assert r.exit_code == 0, r.stderr  # beside the products' folder is fine


def test_a_marked_target_designated_on_the_fly_gets_designates_verdict(sol):
    # `sequence --target <marked id>` designates at the mark itself; it planned without the designation trust
    # model, so a designation that `designate` (and the chain) call NO-GO could be uplinked
    from scipctl.io.downlink import read_downlink
    from scipctl.io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model
    from scipctl.pipeline.designate import designate
    from scipctl.pipeline.predict.from_downlink import resolve_target
    from scipctl.pipeline.stereo_selfcal import self_calibrate_downlink

    dl, _ = self_calibrate_downlink(read_downlink(sol))  # as the command reads it (its default)
    rec, now = resolve_target(dl, "t2", [])
    assert now and rec.designated_from == "mark" and rec.go is not None and rec.p_ok is not None
    im = dl.product(rec.product_id)
    mk = next(t for t in dl.targets if t.id == "t2").mark_in(im.product_id)
    want = designate(dl, im, [mk.u, mk.v], target_id="t2", trust=load_packaged_trust_model(PACKAGED_DESIGNATION))
    assert (rec.p_ok, rec.go) == (want.p_ok, want.go)
    r = runner.invoke(app, ["sequence", str(sol), "--target", "t2", "--json"])
    rule = next(c for c in json.loads(r.stdout)["rules"] if c["rule"] == "designation-go")
    assert rule["ok"] == rec.go and rule["value"] == rec.p_ok
