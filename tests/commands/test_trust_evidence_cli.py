"""`scipctl trust-evidence`: one evidence row per candidate of every marked target; a target the simulator's
record lists as occluded (hidden from the hazcam) gets rows flagged ``occluded`` with no error, and a record that
names a target the hazcam does see is refused (exit 2, no output)."""

import json
import shutil

import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import read_downlink, write_downlink
from scipctl.pipeline.handoff import build_setup
from tests.commands.conftest import SAMPLE

runner = CliRunner()


@pytest.fixture(scope="module")
def hidden_t1(tmp_path_factory):
    """The bundled sample with t1's mark in the answering hazcam removed, as the simulator writes a target that
    image does not see; its .sim.json lists t1 as occluded."""
    d = tmp_path_factory.mktemp("occ")
    dl = read_downlink(SAMPLE)
    haz = build_setup(dl).hazcam.product_id
    t1 = next(t for t in dl.targets if t.id == "t1")
    t1.marks = [m for m in t1.marks if m.product_id != haz]
    path = write_downlink(dl, d / "hid.mcap", "mcap")
    rec = json.loads(SAMPLE.with_name("paper-s1-straight.sim.json").read_text())
    rec["occluded_targets"] = [{"id": "t1"}]
    (d / "hid.sim.json").write_text(json.dumps(rec))
    return path


def test_occluded_target_rows_are_flagged_and_have_no_error(hidden_t1, tmp_path):
    out = tmp_path / "ev.jsonl"
    r = runner.invoke(app, ["trust-evidence", str(hidden_t1), "-o", str(out), "--json"])
    assert r.exit_code == 0, r.stderr
    head, *rows = [json.loads(x) for x in out.read_text().splitlines()]
    # the table says how it was made: version, command line, the downlink's hash; fit-trust's reader skips it
    prov = head["provenance"]
    assert set(head) == {"provenance"} and prov["version"] and prov["command"]  # (here: pytest's argv)
    (fits,) = prov["stereo_selfcal"]  # one downlink: its navcam and hazcam pairs self-calibrated (the default)
    assert fits and {f["camera"] for f in fits} <= {"navcam", "hazcam"}
    assert prov["inputs"]["downlink0"] == {"path": str(hidden_t1), "sha256": read_downlink(hidden_t1).source_sha256}
    # and the .sim.json that gave the rows their family and occluded flags (it was not recorded)
    import hashlib

    sim = hidden_t1.with_name("hid.sim.json")
    assert prov["inputs"]["sim_record0"] == {"path": str(sim), "sha256": hashlib.sha256(sim.read_bytes()).hexdigest()}
    from scipctl.commands.trust import read_rows

    assert len(read_rows([out])) == len(rows)
    by = {}
    for x in rows:
        by.setdefault(x["target"], []).append(x)
    assert set(by) == {"t1", "t2", "t3"}
    assert all(x["occluded"] is True and x["error_px"] is None for x in by["t1"])
    for tid in ("t2", "t3"):  # the other targets as before: an error, and no flag written
        assert all("occluded" not in x and x["error_px"] >= 0 for x in by[tid])
    assert json.loads(r.stdout)["targets"] == 3


def test_a_record_naming_a_seen_target_occluded_is_refused(hidden_t1, tmp_path):
    src = tmp_path / "seen.mcap"
    shutil.copy(hidden_t1, src)
    rec = json.loads(hidden_t1.with_name("hid.sim.json").read_text())
    rec["occluded_targets"] = [{"id": "t2"}]
    src.with_name("seen.sim.json").write_text(json.dumps(rec))
    out = tmp_path / "ev.jsonl"
    r = runner.invoke(app, ["trust-evidence", str(src), "-o", str(out)])
    assert r.exit_code == 2
    assert "occluded_targets" in r.stderr and "t2" in r.stderr and "hazcam" in r.stderr
    assert not out.exists() and "Traceback" not in r.stderr
    rec["occluded_targets"] = [{"id": "nope"}]
    src.with_name("seen.sim.json").write_text(json.dumps(rec))
    r = runner.invoke(app, ["trust-evidence", str(src), "-o", str(out)])
    assert r.exit_code == 2 and "nope" in r.stderr and not out.exists()


def _table_rows(n: int) -> list:
    """The first ``n`` rows of the bundled training table (tests/data/trust/, see its README)."""
    import gzip

    path = SAMPLE.parents[2] / "tests/data/trust/evidence-20dl-11fam.jsonl.gz"
    with gzip.open(path, "rt") as f:
        return [json.loads(next(f)) for _ in range(n)]


@pytest.mark.parametrize("case", ["all-successes", "all-failures", "no-error", "nan-error", "text-evidence",
                                  "no-method"])
def test_fit_trust_refuses_a_table_it_cannot_fit_in_one_line(tmp_path, case):
    # 3 rows all within 1 px gave a constant model (every coefficient 0, p 0.999: GO whatever the evidence) with
    # exit 0; null errors or a text value in the evidence were exit 3
    rows = [r for r in _table_rows(400) if r["error_px"] is not None][:3]
    if case == "all-successes":
        rows = [dict(r, error_px=0.5) for r in rows]
    elif case == "all-failures":
        rows = [dict(r, error_px=50.0) for r in rows]
    elif case == "no-error":
        rows = [dict(r, error_px=None) for r in rows]
    elif case == "nan-error":
        rows = [dict(r, error_px=0.5) for r in rows] + [dict(rows[0], error_px=float("nan"))]
    elif case == "text-evidence":
        rows = [dict(rows[0], evidence=dict(rows[0]["evidence"], app_near_peak="high"))] + rows[1:]
    elif case == "no-method":
        ev = dict(rows[0]["evidence"])
        ev.pop("method")
        rows = [dict(rows[0], evidence=ev)] + rows[1:]
    table = tmp_path / "t.jsonl"
    table.write_text("".join(json.dumps(r, allow_nan=True) + "\n" for r in rows))
    out = tmp_path / "model.json"
    r = runner.invoke(app, ["fit-trust", str(table), "-o", str(out)])
    assert r.exit_code == 2, (r.exit_code, r.stderr)
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("scipctl: error: ")
    assert not out.exists()


def test_a_downlink_named_twice_gives_its_rows_once(hidden_t1, tmp_path):
    # `trust-evidence a.mcap ./a.mcap` used to write every candidate row twice: fit-trust then weighted that
    # downlink twice (campaign and simulate-handoff use each downlink once)
    out1, out2 = tmp_path / "once.jsonl", tmp_path / "twice.jsonl"
    assert runner.invoke(app, ["trust-evidence", str(hidden_t1), "-o", str(out1)]).exit_code == 0
    again = hidden_t1.parent / "." / hidden_t1.name
    r = runner.invoke(app, ["trust-evidence", str(hidden_t1), str(again), "-o", str(out2), "--json"])
    assert r.exit_code == 0, r.stderr
    def rows(path):  # which candidate of which target (the features' last digits vary from run to run)
        return [(d["group"], d["target"], d["sources"]) for d in map(json.loads, path.read_text().splitlines()[1:])]

    once, twice = rows(out1), rows(out2)
    assert len(once) > 0 and twice == once
    assert json.loads(r.stdout)["rows"] == len(once)
    assert "given again: used once" in r.stderr


def test_two_downlinks_of_one_name_stay_two_groups(hidden_t1, tmp_path):
    # a/hid.mcap and b/hid.mcap: their rows used to share the group "hid.mcap", so fit-trust's per-target
    # evaluation (trust_fit.targets_of: (group, target)) merged a's t1 with b's t1
    srcs = []
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        for f in (hidden_t1, hidden_t1.with_name("hid.sim.json")):
            shutil.copy(f, tmp_path / d / f.name)
        srcs.append(str(tmp_path / d / hidden_t1.name))
    out = tmp_path / "ev.jsonl"
    r = runner.invoke(app, ["trust-evidence", *srcs, "-o", str(out), "--json"])
    assert r.exit_code == 0, r.stderr
    rows = [json.loads(x) for x in out.read_text().splitlines()[1:]]
    assert {x["group"] for x in rows} == set(srcs)
    assert json.loads(r.stdout)["targets"] == 6


@pytest.mark.parametrize("family", ["", "  "])
def test_an_empty_family_is_bad_input(tmp_path, family):
    # a script's `--family "$F"` with F unset labelled every row with the family "" (exit 0)
    out = tmp_path / "ev.jsonl"
    r = runner.invoke(app, ["trust-evidence", str(SAMPLE), "--family", family, "-o", str(out)])
    assert r.exit_code == 2, r.output
    assert r.stderr.count("\n") == 1 and "--family" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()


def test_trust_evidence_may_not_overwrite_its_inputs(tmp_path):
    # `-o SRC` replaced the downlink with the evidence table (exit 0); `-o X.sim.json` its simulator's record
    src = tmp_path / "a.mcap"
    shutil.copy(SAMPLE, src)
    shutil.copy(SAMPLE.with_name("paper-s1-straight.sim.json"), tmp_path / "a.sim.json")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for out in (src, tmp_path / "a.sim.json", tmp_path / "." / "a.mcap"):
        r = runner.invoke(app, ["trust-evidence", str(src), "-o", str(out)])
        assert r.exit_code == 2, (out, r.exit_code, r.stderr)
        assert r.stderr.count("\n") == 1 and "would overwrite the input" in r.stderr and "Traceback" not in r.stderr
        assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_fit_trust_may_not_overwrite_its_tables_or_its_model(tmp_path):
    # `-o TABLE` replaced the input table with the model, `--report` = `-o` the model with the report (exit 0)
    table = tmp_path / "t.jsonl"
    table.write_text("".join(json.dumps(r) + "\n" for r in _table_rows(400)))
    before = table.read_bytes()
    model = tmp_path / "m.json"
    for args, option in ((["-o", str(table)], "-o"), (["-o", str(model), "--report", str(table)], "--report"),
                         (["-o", str(model), "--report", str(tmp_path / "." / "m.json")], "--report")):
        r = runner.invoke(app, ["fit-trust", str(table), *args])
        assert r.exit_code == 2, (args, r.exit_code, r.stderr)
        assert r.stderr.count("\n") == 1 and f": {option}: " in r.stderr and "Traceback" not in r.stderr
        assert table.read_bytes() == before and not model.exists()
