"""``scipctl campaign`` from the command line: bad arguments (exit 2, one line, nothing written), a synthetic
campaign on a local cluster, ``--summarize``."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from scipctl.cli import app

ROOT = Path(__file__).resolve().parents[2]
SOL = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
runner = CliRunner()


@pytest.mark.parametrize("args,needle", [
    ([], "SRC"),
    ([str(SOL)], "-o/--out"),
    ([str(SOL), "--synth", "paper", "--seeds", "0", "-o", "{out}"], "not both"),
    (["--synth", "paper", "-o", "{out}"], "--seeds"),
    (["--synth", "paper", "--seeds", "3-1", "-o", "{out}"], "--seeds"),
    (["--synth", "paper", "--seeds", "x", "-o", "{out}"], "--seeds"),
    (["--synth", "volcano", "--seeds", "0", "-o", "{out}"], "volcano"),
    (["--synth", "paper", "--seeds", "0", "--runs", "s9-loop", "-o", "{out}"], "s9-loop"),
    (["--synth", "paper", "--seeds", "0", "--families", "lava-tube", "-o", "{out}"], "lava-tube"),
    ([str(SOL), "--seeds", "0-1", "-o", "{out}"], "only with --synth"),
    ([str(SOL), "--no-errors", "-o", "{out}"], "only with --synth"),
    ([str(SOL), "--error-draws", "1", "-o", "{out}"], "only with --synth"),
    (["--synth", "paper", "--seeds", "0", "--error-draws", "2-1", "-o", "{out}"], "--error-draws"),
    (["--synth", "paper", "--seeds", "0", "--error-draws", "0-2", "--no-errors", "-o", "{out}"], "--error-draws"),
    ([str(SOL), "--methods", "telepathy", "-o", "{out}"], "telepathy"),
    ([str(SOL), "--methods", "pure-kinematic", "--no-handoff", "-o", "{out}"], "--methods"),
    ([str(SOL), "--no-handoff", "--no-chain", "--no-predict", "-o", "{out}"], "nothing left"),
    ([str(SOL), "--no-chain", "--closure", "-o", "{out}"], "--closure"),
    ([str(SOL), "--no-chain", "--chain-answer", "closure", "-o", "{out}"], "--chain-answer: is the chain's answer"),
    ([str(SOL), "--chain-answer", "navcam", "-o", "{out}"], "--chain-answer: must be one of"),
    ([str(SOL), "--success-px", "0", "-o", "{out}"], "--success-px"),
    ([str(SOL), "--workers", "0", "-o", "{out}"], "--workers"),
    ([str(SOL), "--memory-limit", "plenty", "-o", "{out}"], "--memory-limit"),
    ([str(SOL), "--scheduler", "tcp://127.0.0.1:8786", "--workers", "2", "-o", "{out}"], "--workers"),
    (["{tmp}/absent.mcap", "-o", "{out}"], "absent.mcap"),
    (["{tmp}/*.nothing", "-o", "{out}"], "matches no downlink"),
    (["{tmp}", "-o", "{out}"], "no downlinks inside"),
    ([str(SOL), "-o", "{tmp}/a-file"], "not a directory"),
    (["--summarize", "{tmp}/absent"], "--summarize"),
    (["--summarize", "{tmp}", "-o", "{out}"], "--summarize"),
    (["--summarize", "{tmp}"], "manifest"),
])
def test_bad_arguments_exit_2_with_one_line_and_write_nothing(tmp_path, args, needle):
    (tmp_path / "a-file").write_text("x")
    out = tmp_path / "out"
    args = [a.format(out=out, tmp=tmp_path) for a in args]
    r = runner.invoke(app, ["campaign", *args])
    assert r.exit_code == 2, r.output
    assert needle in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()


def test_a_synthetic_campaign_renders_on_the_workers_and_summarizes(tmp_path, monkeypatch):
    """One synthetic downlink (128 x 128 images: SCIPCTL_SYNTH_IMAGE_SCALE, as synth's preview hook) rendered and
    evaluated on a local cluster of one worker; every record carries its scene family and the recipe."""
    monkeypatch.setenv("SCIPCTL_SYNTH_IMAGE_SCALE", "0.125")
    out = tmp_path / "out"
    args = ["campaign", "--synth", "paper", "--seeds", "0", "--runs", "s1-straight", "--workers", "1",
            "--methods", "pure-kinematic,pure-geometric", "--no-chain", "--no-predict", "-o", str(out), "--json"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["run"]["ran"] == 1 and doc["run"]["cluster"]["workers"] == 1
    assert doc["counts"] == {"downlinks": 1, "ok": 1, "failed": 0, "pending": 0, "handoff_records": 12,
                             "chains": 0, "predictions": 0}
    assert set(doc["families"]) == {"default"}
    (rec_file,) = (out / "records").glob("*.jsonl")
    lines = [json.loads(x) for x in rec_file.read_text().splitlines()]
    head, recs = lines[0], lines[1:]
    assert head["downlink"] == "paper-s1-straight-seed0" and head["status"] == "ok"
    recipe = head["provenance"]["inputs"]["synth"]
    assert recipe["recipe"]["image_scale"] == 0.125 and recipe["recipe"]["family"] == "default"
    assert "scipctl synth --scenario paper --seed 0 --runs s1-straight" in recipe["regenerate"]
    assert len(recs) == 12 and all(x["kind"] == "handoff" and x["family"] == "default" for x in recs)
    # the records are the handoff of the same downlink rendered here (self-calibrated, as campaigns do by default)
    from scipctl.pipeline.handoff import build_setup, marked_targets, run_targets
    from scipctl.pipeline.stereo_selfcal import self_calibrate_downlink
    from scipctl.sim.build import build_run

    dl, _ = self_calibrate_downlink(build_run("paper", "s1-straight", 0, image_scale=0.125).downlink)
    assert head["stereo_selfcal"]  # each pair's fit in the records header
    setup = build_setup(dl)
    want = run_targets(dl, setup, marked_targets(dl, setup), methods=["pure-kinematic", "pure-geometric"],
                       downlink_name="paper-s1-straight-seed0")
    assert [x["record"]["predicted_uv"] for x in recs] == [w.predicted_uv for w in want]
    # --summarize re-aggregates the same numbers without running anything
    before = (out / "summary.json").read_text()
    (out / "summary.json").unlink()
    r = runner.invoke(app, ["campaign", "--summarize", str(out), "--json"])
    assert r.exit_code == 0, r.output
    again = json.loads(r.stdout)
    assert again["run"] is None and again["overall"] == doc["overall"] and again["counts"] == doc["counts"]
    assert json.loads((out / "summary.json").read_text())["overall"] == json.loads(before)["overall"]


def test_the_stereo_selfcal_flag_reaches_the_options(tmp_path, monkeypatch):
    """--stereo-selfcal/--no-stereo-selfcal (on by default) is what CampaignOptions.stereo_selfcal says; its effect
    on a downlink is tested in tests/campaign/test_jobs.py."""
    import scipctl.campaign.run as run_mod

    seen = []

    class Stop(Exception):
        pass

    def fake_run(jobs, options, store, cluster, on_start=None, on_result=None):
        seen.append(options)
        raise Stop

    monkeypatch.setattr(run_mod, "run_campaign", fake_run)
    for extra, want in (([], True), (["--stereo-selfcal"], True), (["--no-stereo-selfcal"], False)):
        r = runner.invoke(app, ["campaign", str(SOL), "--no-handoff", "--no-predict", "-o",
                                str(tmp_path / f"o{len(seen)}")] + extra)
        assert "internal error (Stop)" in r.output  # the run was reached (and stopped there)
        assert seen[-1].stereo_selfcal is want
