"""The campaign's pre-uplink prediction of each marked target is what ``scipctl sequence --target`` predicts for it
(same rule checks, same P(success), same risks), run on a worker of the test's Dask cluster."""

import json
import shutil
from pathlib import Path

from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.campaign.results import DownlinkResult
from tests.campaign.records_compare import assert_same

ROOT = Path(__file__).resolve().parents[2]
SOL = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
runner = CliRunner()


def test_predictions_are_those_of_sequence(dask_cluster, tmp_path):
    sol = Path(shutil.copy(SOL, tmp_path / SOL.name))
    out = tmp_path / "out"
    r = runner.invoke(app, ["campaign", str(sol), "-o", str(out), "--scheduler", dask_cluster.address,
                            "--no-handoff", "--no-chain", "--json"])
    assert r.exit_code == 0, r.output
    (path,) = (out / "records").glob("*.jsonl")
    res = DownlinkResult.from_jsonl(path.read_text())
    assert not res.handoff and not res.chains
    from scipctl.io.downlink import read_downlink

    truth = {t.id: t.xyz_site_m.tolist() for t in read_downlink(sol).truth_targets}
    assert res.truth_targets == truth and sorted(truth) == ["t1", "t2", "t3"]  # the header keeps the truth targets
    preds = {p["target"]: p for p in res.predictions}
    assert sorted(preds) == ["t1", "t2", "t3"]  # every marked target
    # one target compared with `sequence` (no handoff.json beside the copy: the default handoff method, as here)
    seq = runner.invoke(app, ["sequence", str(sol), "--target", "t2", "--json"])
    assert seq.exit_code in (0, 1), seq.output
    want = json.loads(seq.stdout)
    got = preds["t2"]
    assert got["sequence_written"] == want["ok"]
    assert_same(got["rules"], want["rules"], 0.0, "rules")
    assert_same(got["prediction"]["risks"], want["risks"], 0.0, "risks")
    assert got["confidence"] == want["confidence"] and got["designated_now"] == want["designated_now"]
    assert got["rules_file"] == want["rules_file"]  # the same built-in, chosen for the same reason
    if want["ok"]:
        assert got["commands"] == want["commands"] and got["total_duration_s"] == want["total_duration_s"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["overall"]["prediction"]["targets"] == 3
    assert summary["overall"]["prediction"]["sequences_written"] == sum(p["sequence_written"] for p in preds.values())
