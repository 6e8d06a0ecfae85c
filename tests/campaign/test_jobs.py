"""The downlinks of a campaign: SRC arguments (files, folders of downlinks, globs), seeds, synthetic recipes,
scene families, and which records count as done."""

import json
import shutil
from pathlib import Path

import pytest

from scipctl.campaign.jobs import (DEFAULT_FAMILY, FILES_FAMILY, expand_sources, file_jobs, known_families,
                                   parse_seeds, synth_jobs)
from scipctl.campaign.options import CampaignOptions, job_key
from scipctl.campaign.results import DownlinkResult
from scipctl.campaign.store import CampaignStore
from scipctl.errors import InputError

ROOT = Path(__file__).resolve().parents[2]
SOLS = ROOT / "sample_sols"


def test_folders_globs_and_files_expand_to_each_downlink_once(tmp_path):
    mcaps = sorted((SOLS / "mcap").glob("*.mcap"))
    dirs = sorted(p for p in (SOLS / "dir").iterdir() if p.is_dir())
    # a folder of downlinks: its .mcap files and downlink folders, at any depth, hidden folders skipped
    nest = tmp_path / "a" / "b"
    nest.mkdir(parents=True)
    shutil.copy(mcaps[0], nest / "x.mcap")
    (tmp_path / ".hidden").mkdir()
    shutil.copy(mcaps[1], tmp_path / ".hidden" / "y.mcap")
    assert expand_sources([tmp_path]) == [nest / "x.mcap"]
    assert expand_sources([SOLS / "dir"]) == dirs  # downlink folders, not the images inside them
    assert expand_sources([dirs[0]]) == [dirs[0]]  # a downlink folder is one downlink
    got = expand_sources([SOLS / "mcap", str(SOLS / "mcap" / "*.mcap"), mcaps[0]])
    assert got == mcaps  # the same file through a folder, a glob and by name: once
    assert expand_sources([str(SOLS / "**" / "*.mcap")]) == mcaps


def test_file_jobs_hash_name_and_family(tmp_path):
    from scipctl.io.provenance import sha256_file

    sol = SOLS / "mcap" / "paper-s1-arc.mcap"
    plain = Path(shutil.copy(sol, tmp_path / sol.name))  # no simulation record beside it
    (job,) = file_jobs([sol, plain])  # same name, same bytes: one job (the first)
    assert job.family == DEFAULT_FAMILY and job.input_sha256 == sha256_file(sol) and job.path == str(sol.resolve())
    (copy,) = file_jobs([plain])
    assert copy.family == FILES_FAMILY and copy.job_id == job.job_id
    renamed = Path(shutil.copy(sol, tmp_path / "other-name.mcap"))
    assert file_jobs([renamed])[0].job_id != job.job_id  # another name: another job (the records' downlink field)
    (tmp_path / "paper-s1-arc.sim.json").write_text(json.dumps({"family": "sand-sheet"}))
    assert file_jobs([plain])[0].family == "sand-sheet"
    # what `synth --family` writes: the realised family's record (its name is the family)
    from scipctl.sim.families import FAMILIES

    (tmp_path / "paper-s1-arc.sim.json").write_text(json.dumps({"family": FAMILIES["errors-double"].to_dict()}))
    assert file_jobs([plain])[0].family == "errors-double"


@pytest.mark.parametrize("text,seeds", [("0-3", [0, 1, 2, 3]), ("5", [5]), ("1,3-4,1", [1, 3, 4])])
def test_parse_seeds(text, seeds):
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize("text", ["3-1", "-1", "a", "", "1-b", "0-999999999999", "0-99999,100000"])
def test_bad_seeds(text):
    with pytest.raises(InputError, match="--seeds"):
        parse_seeds(text)


def test_synth_jobs_name_each_recipe_and_hash_it():
    jobs = synth_jobs("paper", [0, 1], ["s1-straight", "s2-arc"])
    assert [j.name for j in jobs] == ["paper-s1-straight-seed0", "paper-s2-arc-seed0", "paper-s1-straight-seed1",
                                      "paper-s2-arc-seed1"]
    assert all(j.family == DEFAULT_FAMILY and j.path is None for j in jobs)
    assert len({j.input_sha256 for j in jobs}) == 4  # every recipe its own identity
    assert synth_jobs("paper", [0], ["s1-straight"])[0].input_sha256 == jobs[0].input_sha256  # and a stable one
    assert synth_jobs("paper", [0], ["s1-straight"], no_errors=True)[0].input_sha256 != jobs[0].input_sha256
    assert len(synth_jobs("paper", [0])) == 6  # every run of the scenario by default
    assert "default" in known_families()


def test_done_means_same_key_and_ok(tmp_path):
    opts = CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "near"),))
    job = synth_jobs("paper", [0], ["s1-straight"])[0]
    key = job_key(job.input_sha256, opts.key())
    store = CampaignStore(tmp_path / "out")
    assert not store.is_done(job, key)  # nothing yet (and nothing made: the folder waits for a first write)
    assert not (tmp_path / "out").exists()
    store.make()
    store.write(DownlinkResult(job, key))
    assert store.is_done(job, key)
    other = CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "far"),))
    assert not store.is_done(job, job_key(job.input_sha256, other.key()))
    failed = DownlinkResult(job, key)
    failed.fail("load", InputError("x.mcap", "header", "bad magic"))
    store.write(failed)
    assert not store.is_done(job, key)  # a failed downlink runs again
    assert store.read(job.job_id).error == "load: x.mcap: header: bad magic"


def test_the_closure_option_changes_the_key_only_when_on():
    """--closure (the chain's closure check) is part of what a downlink's records were made with, but campaigns
    without it keep the key they had before the option existed."""
    import hashlib

    from scipctl import __version__

    opts = CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "near"),), chain_answer="handoff",
                           stereo_selfcal=False)  # a campaign with none of the options that came later
    before = {"handoff": True, "chain": True, "predict": True, "methods": ["pure-kinematic"],
              "pairs": [["pure-kinematic", "near"]], "success_px": 4.0, "fast": False, "predict_route": "plan"}
    text = json.dumps({"options": before, "version": __version__}, sort_keys=True)
    assert opts.key() == hashlib.sha256(text.encode()).hexdigest()
    on = CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "near"),), closure=True,
                         chain_answer="handoff", stereo_selfcal=False).check()
    assert on.key() != opts.key() and on.to_dict()["closure"] is True
    assert CampaignOptions.from_dict(on.to_dict()) == on and CampaignOptions.from_dict(opts.to_dict()) == opts
    with pytest.raises(InputError, match="--closure"):
        CampaignOptions(handoff=False, chain=False, closure=True).check()
    # --chain-answer: campaigns made before it were "handoff" ones and keep their key; the default ("closure")
    # is in the key, so a campaign re-run with today's default does its chains again
    ans = CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "near"),))
    assert ans.chain_answer == "closure" and ans.key() not in (opts.key(), on.key())
    assert ans.to_dict()["chain_answer"] == "closure"
    assert "chain_answer" not in opts.to_dict() and CampaignOptions.from_dict(ans.to_dict()) == ans
    with pytest.raises(InputError, match="--chain-answer"):
        CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "near"),), chain_answer="x").check()


def test_the_closure_option_reaches_every_chain(monkeypatch):
    """campaign --closure and --chain-answer: the task asks run_marked_chains for them, which runs each chain with
    them in its ChainParams (the check and the answer are tested in tests/pipeline/test_chain.py)."""
    import scipctl.pipeline.chain as chain_mod
    from scipctl.campaign import task
    from scipctl.io.downlink import read_downlink

    seen = []

    def fake_run_chain(dl, start, uv, target_id=None, setups=None, params=None, feature_cache=None):
        seen.append(None if params is None else (params.closure, params.answer))
        return []

    monkeypatch.setattr(chain_mod, "run_chain", fake_run_chain)
    monkeypatch.setattr("scipctl.pipeline.chain_trust.chain_verdict",
                        lambda steps: type("V", (), {"to_dict": lambda self: {}})())
    dl = read_downlink(SOLS / "mcap" / "paper-s1-arc.mcap")
    job = file_jobs([SOLS / "mcap" / "paper-s1-arc.mcap"])[0]
    for closure, answer, want in ((True, "handoff", (True, "handoff")), (False, None, (False, "closure")),
                                  (False, "closure", (False, "closure"))):
        seen.clear()
        task._chain(dl, job, DownlinkResult(job, "k"), closure, answer)
        assert seen and all(s == want for s in seen), (closure, answer, seen)


def test_stereo_selfcal_is_in_the_key_only_when_on_and_runs_before_the_stages(monkeypatch):
    """campaign --stereo-selfcal (the default): campaigns without it (--no-stereo-selfcal, and those made before it)
    keep their key; with it, the stages see the re-aligned right models (pipeline/stereo_selfcal.py, tested in
    tests/pipeline/test_stereo_selfcal.py) and the header records each pair's fit."""
    from scipctl.campaign import task
    from scipctl.campaign.options import job_key

    off = CampaignOptions(handoff=False, chain=True, predict=False, stereo_selfcal=False)
    on = CampaignOptions(handoff=False, chain=True, predict=False).check()
    assert on.stereo_selfcal is True  # the default
    assert "stereo_selfcal" not in off.to_dict() and on.to_dict()["stereo_selfcal"] is True
    assert on.key() != off.key() and CampaignOptions.from_dict(on.to_dict()) == on
    assert CampaignOptions.from_dict(off.to_dict()) == off
    seen = {}

    def fake_chain(dl, job, res, closure=False, answer=None):
        seen.update({im.product_id: im.camera_model for im in dl.images})

    monkeypatch.setattr(task, "_chain", fake_chain)
    job = file_jobs([SOLS / "mcap" / "paper-s1-arc.mcap"])[0]
    res = task.run_job(job, on, job_key(job.input_sha256, on.key()))
    assert res.status == "ok", res.error
    applied = [p for p in res.stereo_selfcal if p["applied"]]
    assert len(res.stereo_selfcal) == 6 and applied
    from scipctl.io.downlink import read_downlink

    given = {im.product_id: im.camera_model for im in read_downlink(SOLS / "mcap" / "paper-s1-arc.mcap").images}
    for p in applied:
        assert not seen[p["right"]].almost_equal(given[p["right"]], tol=1e-12)
        assert seen[p["left"]].almost_equal(given[p["left"]], tol=0)
    back = DownlinkResult.from_jsonl(res.to_jsonl())
    assert back.stereo_selfcal == json.loads(json.dumps(res.stereo_selfcal))


@pytest.mark.parametrize("family", ["errors-double", "errors-none", "sand-sheet"])
def test_a_synthetic_job_renders_what_synth_renders_for_its_family(family):
    """campaign --synth --families F and `synth --family F` give the same downlink: the family's error scale
    included (before session 32 the campaign passed the scenario's default errors, so errors-double and
    errors-none rendered with today's errors)."""
    from scipctl.campaign.task import load_downlink
    from scipctl.sim.build import build_run

    job = synth_jobs("paper", [3], ["s1-straight"], [family], image_scale=0.125, supersample=1)[0]
    want = build_run("paper", "s1-straight", 3, image_scale=0.125, supersample=1, family=family).downlink
    got = load_downlink(job)
    assert [im.png for im in got.images] == [im.png for im in want.images]


def test_a_family_jobs_identity_changed_with_its_errors_and_the_default_did_not():
    import hashlib
    import json

    from scipctl import __version__

    plain = synth_jobs("paper", [0], ["s1-straight"])[0]
    old = json.dumps({"synth": plain.synth.to_dict(), "version": __version__}, sort_keys=True)
    assert plain.input_sha256 == hashlib.sha256(old.encode()).hexdigest()  # default-family campaigns resume as before
    fam = synth_jobs("paper", [0], ["s1-straight"], ["errors-double"])[0]
    old = json.dumps({"synth": fam.synth.to_dict(), "version": __version__}, sort_keys=True)
    assert fam.input_sha256 != hashlib.sha256(old.encode()).hexdigest()


def test_error_draws_make_one_job_per_draw_named_and_hashed():
    jobs = synth_jobs("paper", [5], ["s1-straight"], ["sand-sheet"], error_draws=[0, 1, 2])
    assert [j.name for j in jobs] == ["paper-s1-straight-seed5-sand-sheet", "paper-s1-straight-seed5-sand-sheet-d1",
                                      "paper-s1-straight-seed5-sand-sheet-d2"]
    assert jobs[0].input_sha256 == synth_jobs("paper", [5], ["s1-straight"], ["sand-sheet"])[0].input_sha256
    assert len({j.input_sha256 for j in jobs}) == 3
    assert "error_draw" not in jobs[0].synth.to_dict() and jobs[2].synth.to_dict()["error_draw"] == 2
    for j in jobs:
        assert type(j.synth).from_dict(j.synth.to_dict()) == j.synth
    assert jobs[2].synth.regenerate_command() == ("scipctl synth --scenario paper --seed 5 --runs s1-straight "
                                                  "--family sand-sheet --error-draw 2 -o OUT")
    with pytest.raises(InputError, match="--error-draws"):
        synth_jobs("paper", [5], ["s1-straight"], error_draws=[1], no_errors=True)
    with pytest.raises(InputError, match="--error-draws"):
        synth_jobs("paper", [5], ["s1-straight"], error_draws=[-1])
    assert parse_seeds("0-2", "--error-draws") == [0, 1, 2]
    with pytest.raises(InputError, match="--error-draws"):
        parse_seeds("x", "--error-draws")


def test_a_drawn_job_renders_what_synth_error_draw_renders():
    from scipctl.campaign.task import load_downlink
    from scipctl.sim.build import build_run

    job = synth_jobs("paper", [3], ["s1-straight"], error_draws=[2], image_scale=0.125, supersample=1)[0]
    want = build_run("paper", "s1-straight", 3, image_scale=0.125, supersample=1, error_draw=2).downlink
    assert [im.png for im in load_downlink(job).images] == [im.png for im in want.images]


def test_records_keep_the_truth_targets():
    job = synth_jobs("paper", [0], ["s1-straight"])[0]
    res = DownlinkResult(job, "k", truth_targets={"t1": [1.0, 2.0, 0.5]})
    back = DownlinkResult.from_jsonl(res.to_jsonl())
    assert back.truth_targets == {"t1": [1.0, 2.0, 0.5]}
    assert DownlinkResult.from_jsonl(DownlinkResult(job, "k").to_jsonl()).truth_targets == {}


def test_the_self_calibration_fits_the_pairs_the_stages_read():
    """A campaign without the chain fits fewer pairs: the handoff's navcam and hazcam pairs, the prediction's at each
    marked target's designation stop (what `simulate-handoff` and `sequence` fit); with the chain, all. (A pair's
    fit reads that pair alone: tests/pipeline/test_stereo_selfcal.py.)"""
    from scipctl.campaign.task import _pairs_read
    from scipctl.io.downlink import read_downlink

    dl = read_downlink(SOLS / "mcap" / "paper-s1-straight.mcap")
    lefts = [im for im in dl.images if im.eye == "left"]

    def picked(**kw):
        only = _pairs_read(dl, CampaignOptions(**kw))
        return None if only is None else sorted(im.product_id for im in lefts if only(im))

    assert picked(handoff=True, chain=True, predict=True) is None
    assert picked(handoff=True, chain=False, predict=False) == sorted(
        im.product_id for im in lefts if im.camera in ("navcam", "hazcam"))
    assert picked(handoff=False, chain=False, predict=True) == ["s1-straight-pan10-pancam-L"]  # the marks' first stop
    assert picked(handoff=True, chain=False, predict=True) == sorted(
        ["s1-straight-pan10-pancam-L"] + [im.product_id for im in lefts if im.camera in ("navcam", "hazcam")])
