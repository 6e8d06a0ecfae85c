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
    assert prov["inputs"]["downlink0"] == {"path": str(hidden_t1), "sha256": read_downlink(hidden_t1).source_sha256}
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
