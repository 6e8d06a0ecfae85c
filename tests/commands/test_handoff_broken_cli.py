"""`scipctl simulate-handoff` on a deliberately broken downlink (issue #14 item 6): the command's answer is NO-GO,
exit code 1, with the packaged trust model, end to end (the broken downlink written to disk and read back)."""

import json
from pathlib import Path

from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import read_downlink, write_downlink
from scipctl.pipeline.handoff import find_products
from tests.pipeline import broken_downlinks as B

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
runner = CliRunner()


def test_target_occluded_in_the_hazcams_exits_1(tmp_path):
    """t1 hidden from both hazcams by a textured disk ~40 cm in front of it (as in
    tests/pipeline/test_handoff_broken.py): no hazcam pixel is right, so scip must say NO-GO and the command exit 1,
    its JSON (every record) still on stdout."""
    dl = read_downlink(SAMPLE)
    haz, _, _ = find_products(dl)
    broken = B.encode_pixels(B.occluded_copy(dl, haz, ["t1"], 0.06, 0.6, seed=7))
    path = write_downlink(broken, tmp_path / "occluded.mcap")
    r = runner.invoke(app, ["simulate-handoff", str(path), "--target", "t1", "--json"])
    assert r.exit_code == 1, r.stderr
    assert "NO-GO" in r.stderr
    recs = json.loads(r.stdout)["results"]
    scip = [x for x in recs if x["method"] == "scip"]
    assert len(scip) == 1 and scip[0]["go"] is False and scip[0]["p_success"] is not None
