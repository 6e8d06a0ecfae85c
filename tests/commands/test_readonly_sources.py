"""Commands on downlinks and workspaces in read-only folders, and --products-dir, through the CLI (CliRunner).

Read-only folders are simulated in-process by tests.io.readonly_fs (chmod does not stop root, and CI runs as
root); afterwards the real folder listing is compared: nothing may have been written beside the source."""

import hashlib
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import read_downlink
from tests.io.readonly_fs import make_read_only, tree

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
runner = CliRunner()


def _key(p: Path) -> str:
    return f"{p.name}-{hashlib.sha256(str(p.resolve()).encode()).hexdigest()[:12]}"


def _point_mark(dl):
    """(pixel "u,v", product id) of the point target's mark in the latest left pancam image."""
    latest = max((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    t = next(t for t in dl.targets if t.kind == "point")
    mk = t.mark_in(latest.product_id)
    return f"{mk.u},{mk.v}", latest.product_id


@pytest.fixture
def archive(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("SCIPCTL_PRODUCTS_DIR", raising=False)
    (tmp_path / "archive").mkdir()
    p = tmp_path / "archive" / SAMPLE.name
    shutil.copy(SAMPLE, p)
    return p


def test_read_only_downlink_designate_handoff_then_sequence_reads_them_back(tmp_path, archive, monkeypatch):
    pixel, product = _point_mark(read_downlink(archive))
    before = tree(archive.parent)
    make_read_only(monkeypatch, archive.parent)
    cache = tmp_path / "cache" / "scipctl" / "sidecars" / _key(archive)

    r = runner.invoke(app, ["designate", str(archive), "--camera", "pancam", "--pixel", pixel, "--id", "r1", "--json"])
    assert r.exit_code == 0, r.stderr
    rec = json.loads(r.stdout)
    assert rec["id"] == "r1" and rec["product_id"] == product and rec["saved_to"] == str(cache / "targets.json")
    notes = [ln for ln in r.stderr.splitlines() if ln.startswith("scipctl: note: ")]
    assert len(notes) == 1 and str(cache) in notes[0] and "not writable" in notes[0]

    r = runner.invoke(app, ["simulate-handoff", str(archive), "--methods", "pure-kinematic", "--json"])
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["downlinks"][0]["saved_to"] == str(cache / "handoff.json")
    assert str(cache) in r.stderr

    # r1 exists only in the designation saved in the per-user folder: sequence must find it there
    r = runner.invoke(app, ["sequence", str(archive), "--target", "r1", "--json"])
    assert r.exit_code in (0, 1), r.stderr  # 1: a flight rule may say no; the summary is printed either way
    summary = json.loads(r.stdout)
    assert summary["target"] == "r1" and summary["designated_now"] is False
    assert summary["products_read"] == {"targets.json": str(cache / "targets.json"),
                                        "handoff.json": str(cache / "handoff.json")}

    r = runner.invoke(app, ["info", str(archive), "--json"])
    assert json.loads(r.stdout)["products"] == {"handoff.json": str(cache / "handoff.json"),
                                                "stereo_selfcal.json": str(cache / "stereo_selfcal.json"),
                                                "targets.json": str(cache / "targets.json")}
    assert tree(archive.parent) == before  # nothing written beside the source
    # no temporary files (stereo_selfcal.json: the fits the commands kept for each other, commands/selfcal.py)
    assert sorted(p.name for p in cache.iterdir()) == ["handoff.json", "stereo_selfcal.json", "targets.json"]


def test_read_only_workspace_is_exit_2_naming_the_folder_then_products_dir_works(tmp_path, archive, monkeypatch):
    ws = tmp_path / "ws"
    assert runner.invoke(app, ["ingest", str(archive), "-o", str(ws)]).exit_code == 0
    pixel, _ = _point_mark(read_downlink(archive))
    before = tree(ws)
    make_read_only(monkeypatch, ws / "scipctl")

    r = runner.invoke(app, ["designate", str(ws), "--camera", "pancam", "--pixel", pixel, "--id", "r1"])
    assert r.exit_code == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith(f"scipctl: error: {ws / 'scipctl'}: products: ")
    assert "not writable" in r.stderr and "--products-dir" in r.stderr and "Traceback" not in r.stderr
    assert tree(ws) == before and not (tmp_path / "cache").exists()  # no silent fallback for a workspace

    prod = tmp_path / "prod"
    r = runner.invoke(app, ["designate", str(ws), "--camera", "pancam", "--pixel", pixel, "--id", "r1",
                            "--products-dir", str(prod), "--json"])
    assert r.exit_code == 0, r.stderr
    saved = prod / _key(ws) / "targets.json"
    assert json.loads(r.stdout)["saved_to"] == str(saved)
    assert f"scipctl: note: products of {ws} go to {saved.parent}/" in r.stderr
    # the environment variable names the same place; info reads the product back from there
    r = runner.invoke(app, ["info", str(ws), "--json"], env={"SCIPCTL_PRODUCTS_DIR": str(prod)})
    doc = json.loads(r.stdout)
    fits = saved.parent / "stereo_selfcal.json"  # the designation's fit, kept for the next command
    assert doc["products"] == {"stereo_selfcal.json": str(fits), "targets.json": str(saved)}
    assert doc["workspace"]["products"] == ["stereo_selfcal.json", "targets.json"]
    assert [t["id"] for t in json.loads(saved.read_text())["targets"]] == ["r1"]
    assert tree(ws) == before


def test_products_dir_that_is_a_file_is_exit_2(tmp_path, archive):
    (tmp_path / "afile").write_text("x")
    r = runner.invoke(app, ["designate", str(archive), "--camera", "pancam", "--pixel", "500,500",
                            "--products-dir", str(tmp_path / "afile")])
    assert r.exit_code == 2
    assert r.stderr == f"scipctl: error: {tmp_path / 'afile'}: products-dir: exists and is not a directory\n"


@pytest.mark.parametrize("command", [["designate", "--camera", "pancam", "--pixel", "500,500"], ["info"]])
def test_an_empty_products_dir_is_exit_2(tmp_path, archive, monkeypatch, command):
    # `--products-dir "$D"` with D unset: the CLI read "" as ".", and products went to the current folder
    monkeypatch.chdir(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    r = runner.invoke(app, [command[0], str(archive), *command[1:], "--products-dir", ""])
    assert r.exit_code == 2, r.output
    assert r.stderr == ("scipctl: error: --products-dir: products-dir: empty: give a value, or leave the option "
                         "out\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == before
