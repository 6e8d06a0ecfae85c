"""``scipctl ingest`` and ``scipctl info`` through the CLI (CliRunner), plus one real subprocess."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import downlink_differences, read_downlink, write_downlink
from tests.io.builders import make_small_downlink

REPO = Path(__file__).resolve().parents[2]
runner = CliRunner()


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    d = tmp_path_factory.mktemp("dl")
    dl = make_small_downlink()
    write_downlink(dl, d / "sol42.mcap")
    return dl, d / "sol42.mcap"


def test_ingest_json_summary_and_workspace(tmp_path, small):
    dl, src = small
    ws = tmp_path / "ws"
    r = runner.invoke(app, ["ingest", str(src), "-o", str(ws), "--json"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)  # exactly one JSON document on stdout
    assert doc["workspace"] == str(ws)
    sha = read_downlink(src).source_sha256
    assert doc["provenance"]["tool"] == "scipctl" and doc["provenance"]["inputs"]["downlink"]["sha256"] == sha
    info = json.loads(runner.invoke(app, ["info", str(src), "--json"]).stdout)
    assert info["provenance"]["inputs"]["downlink"]["sha256"] == sha
    s = doc["summary"]
    assert (s["mission"], s["sol"], s["format_version"]) == ("test", 42, "1")
    assert s["counts"] == {"images": len(dl.images), "positions": 2, "targets": len(dl.targets)}
    # positions with poses
    p0 = s["positions"][0]
    assert (p0["site"], p0["drive"]) == (1, 0)
    yaw, _, _ = dl.images[0].pose.yaw_pitch_roll_rad
    assert p0["pose"]["yaw_deg"] == pytest.approx(np.degrees(yaw), abs=1e-9)
    assert p0["pose"]["x_m"] == dl.images[0].pose.position_m[0]
    assert p0["cameras"] == {"pancam": ["left", "right"], "navcam": ["left", "right"], "hazcam": ["left", "right"]}
    assert s["positions"][1]["cameras"] == {"navcam": ["left", "right"], "hazcam": ["left", "right"]}
    # image statistics computed from the pixels themselves
    for rec in s["images"]:
        px = dl.product(rec["product_id"]).pixels
        assert rec["mean"] == pytest.approx(px.mean() / 255.0, rel=1e-12)
        assert rec["saturated_fraction"] == pytest.approx(np.mean(px == 255), rel=1e-12)
        im = dl.product(rec["product_id"])
        if im.mast is not None:
            assert rec["pan_deg"] == pytest.approx(np.degrees(im.mast.pan_rad))
        else:
            assert rec["pan_deg"] is None and im.camera == "hazcam"
    assert [t["id"] for t in s["targets"]] == [t.id for t in dl.targets]
    assert len(s["targets"][0]["marks"]) == len(dl.targets[0].marks)
    assert s["truth"] == {"present": True, "images": len(dl.truth_images), "targets": len(dl.truth_targets)}
    # the workspace is a valid downlink holding the same content, with the summary stored
    assert downlink_differences(read_downlink(src), read_downlink(ws)) == []
    stored = json.loads((ws / "scipctl" / "workspace.json").read_text())
    assert stored["summary"]["counts"] == s["counts"]


def test_ingest_prints_tables_on_stderr_only(tmp_path, small):
    _, src = small
    r = runner.invoke(app, ["ingest", str(src), "-o", str(tmp_path / "ws")], env={"COLUMNS": "160"})
    assert r.exit_code == 0
    assert r.stdout == ""
    assert "Rover positions" in r.stderr and "navcam_left_1_12" in r.stderr and "Simulation truth: present" in r.stderr


def test_info_on_workspace_and_raw_downlink(tmp_path, small):
    _, src = small
    ws = tmp_path / "ws"
    assert runner.invoke(app, ["ingest", str(src), "-o", str(ws)]).exit_code == 0
    (ws / "scipctl" / "targets.json").write_text("{}")
    r = runner.invoke(app, ["info", str(ws), "--json"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["workspace"]["products"] == ["targets.json"]
    assert doc["workspace"]["ingested_from"]["path"] == str(src)
    r2 = runner.invoke(app, ["info", str(src), "--json"])
    raw = json.loads(r2.stdout)
    assert "workspace" not in raw
    assert raw["images"] == doc["images"] and raw["positions"] == doc["positions"]
    assert not list(tmp_path.glob("*.scipctl"))  # info writes nothing


def test_info_without_truth_or_targets(tmp_path):
    write_downlink(make_small_downlink(with_targets=False, with_truth=False, n_positions=1), tmp_path / "x.mcap")
    r = runner.invoke(app, ["info", str(tmp_path / "x.mcap")])
    assert r.exit_code == 0
    assert "Simulation truth: none" in r.stderr and "Targets" not in r.stderr


def test_bad_input_is_exit_2_with_one_line(tmp_path, small):
    _, src = small
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(src.read_bytes()[:-100])
    r = runner.invoke(app, ["ingest", str(bad), "-o", str(tmp_path / "ws")])
    assert r.exit_code == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("scipctl: error: ") and str(bad) in r.stderr
    assert not (tmp_path / "ws").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["bad.mcap"]  # no temporary directory left either


def test_output_inside_or_containing_the_source_is_refused(tmp_path):
    write_downlink(make_small_downlink(n_positions=1), tmp_path / "dl", container="dir")
    r = runner.invoke(app, ["ingest", str(tmp_path / "dl"), "-o", str(tmp_path / "dl" / "ws")])
    assert r.exit_code == 2 and "inside the source" in r.stderr
    (tmp_path / "box").mkdir()
    write_downlink(make_small_downlink(n_positions=1), tmp_path / "box" / "x.mcap")
    r = runner.invoke(app, ["ingest", str(tmp_path / "box" / "x.mcap"), "-o", str(tmp_path / "box")])
    assert r.exit_code == 2 and (tmp_path / "box" / "x.mcap").exists()


def test_reingest_a_workspace_in_place(tmp_path, small):
    _, src = small
    ws = tmp_path / "ws"
    assert runner.invoke(app, ["ingest", str(src), "-o", str(ws)]).exit_code == 0
    r = runner.invoke(app, ["ingest", str(ws), "-o", str(ws), "--json"])
    assert r.exit_code == 0, r.stderr
    assert downlink_differences(read_downlink(src), read_downlink(ws)) == []


def test_real_subprocess_exit_code_and_clean_stderr(tmp_path):
    exe = REPO / ".venv" / "bin" / "scipctl"
    if not exe.exists():
        exe = Path(sys.executable).with_name("scipctl")
    bad = tmp_path / "broken.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x01" * 50)
    out = tmp_path / "ws"
    r = subprocess.run([str(exe), "ingest", str(bad), "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stdout == ""
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("scipctl: error: ") and "broken.mcap" in lines[0]
    assert "Traceback" not in r.stderr
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["broken.mcap"]


SAMPLES = REPO / "sample_sols" / "mcap"


@pytest.fixture(scope="module")
def ws_with_products(tmp_path_factory):
    """A workspace of a sample sol holding a real designation (targets.json) and handoff results (handoff.json)."""
    d = tmp_path_factory.mktemp("reingest")
    src = d / "paper-s1-straight.mcap"
    shutil.copy(SAMPLES / src.name, src)
    ws = d / "ws"
    assert runner.invoke(app, ["ingest", str(src), "-o", str(ws)]).exit_code == 0
    dl = read_downlink(src)
    latest = max((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = next(t for t in dl.targets if t.kind == "point").mark_in(latest.product_id)
    r = runner.invoke(app, ["designate", str(ws), "--camera", "pancam", "--pixel", f"{mk.u},{mk.v}", "--id", "r1"])
    assert r.exit_code == 0, r.stderr
    r = runner.invoke(app, ["simulate-handoff", str(ws), "--methods", "pure-kinematic"])
    assert r.exit_code == 0, r.stderr
    assert sorted(p.name for p in (ws / "scipctl").iterdir()) == MADE + ["workspace.json"]
    return src, ws


# what the fixture's commands leave in the workspace (stereo_selfcal.json: the fits they keep for each other)
MADE = ["handoff.json", "stereo_selfcal.json", "targets.json"]


def _products(ws):
    return {p.name: p.read_bytes() for p in (ws / "scipctl").iterdir() if p.name != "workspace.json"}


def test_reingest_keeps_designations_and_handoff_results(tmp_path, ws_with_products):
    src, ws0 = ws_with_products
    ws = tmp_path / "ws"
    shutil.copytree(ws0, ws)
    made = _products(ws)
    r = runner.invoke(app, ["ingest", str(src), "-o", str(ws), "--json"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["kept_products"] == MADE and doc["superseded_products"] == []
    assert f"scipctl: note: kept the products of the existing workspace {ws}: {', '.join(MADE)}\n" in r.stderr
    assert _products(ws) == made
    assert json.loads((ws / "scipctl" / "workspace.json").read_text())["kept_products"] == MADE
    r = runner.invoke(app, ["ingest", str(ws), "-o", str(ws), "--json"])  # in place
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["kept_products"] == MADE and _products(ws) == made
    # and the commands still find them: designate adds to r1 rather than starting over
    info = json.loads(runner.invoke(app, ["info", str(ws), "--json"]).stdout)
    assert info["workspace"]["products"] == MADE
    assert [t["id"] for t in json.loads((ws / "scipctl" / "targets.json").read_text())["targets"]] == ["r1"]


def test_reingest_of_a_different_downlink_needs_force(tmp_path, ws_with_products):
    src, ws0 = ws_with_products
    ws = tmp_path / "ws"
    shutil.copytree(ws0, ws)
    made = _products(ws)
    other = tmp_path / "paper-s1-arc.mcap"
    shutil.copy(SAMPLES / other.name, other)
    before = {p.relative_to(ws).as_posix(): (p.stat().st_mtime_ns, p.read_bytes() if p.is_file() else None)
              for p in sorted(ws.rglob("*"))}
    r = runner.invoke(app, ["ingest", str(other), "-o", str(ws)])
    assert r.exit_code == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith(f"scipctl: error: {ws}: source: ")
    assert "--force" in r.stderr and "targets.json" in r.stderr and "Traceback" not in r.stderr
    after = {p.relative_to(ws).as_posix(): (p.stat().st_mtime_ns, p.read_bytes() if p.is_file() else None)
             for p in sorted(ws.rglob("*"))}
    assert after == before  # nothing changed on disk
    assert sorted(p.name for p in tmp_path.iterdir()) == ["paper-s1-arc.mcap", "ws"]  # no temporary left

    r = runner.invoke(app, ["ingest", str(other), "-o", str(ws), "--force", "--json"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["kept_products"] == [] and doc["superseded_products"] == MADE
    sup = Path(doc["superseded_dir"])
    assert sup.parent == ws / "scipctl" and sup.name.startswith("superseded-")
    assert {n: (sup / n).read_bytes() for n in made} == made  # set aside, byte for byte
    assert json.loads((sup / "workspace.json").read_text())["source"]["path"] == str(src)
    assert "set aside in" in r.stderr and str(sup) in r.stderr
    assert downlink_differences(read_downlink(other), read_downlink(ws)) == []
    info = json.loads(runner.invoke(app, ["info", str(ws), "--json"]).stdout)
    assert info["workspace"]["products"] == [] and info["products"] == {}


@pytest.mark.parametrize("replicate", [False, True])
def test_image_stats_judge_12_bit_data_against_its_own_full_scale(replicate):
    # A real EDR's 12-bit samples in 16-bit words: a fifth of the rows at 4095 is a fifth saturated, and the mean
    # is a fraction of 4095 (against 65535 it read 0 % saturated and 16 times darker than the report said). The
    # same samples bit-replicated to 16 bits (the simulator's encoding) give the same figures.
    from scipctl.commands.ingest import image_stats
    from scipctl.io.images import encode_png
    from scipctl.model import ImageProduct

    v12 = np.full((100, 50), 1024, np.uint16)
    v12[:20] = 4095
    px = (v12 << 4) | (v12 >> 8) if replicate else v12
    im = ImageProduct(product_id="p", camera="navcam", eye="left", time_s=0.0, site=1, drive=0, pose=None,
                      camera_model=None, width=50, height=100, png=encode_png(px), _pixels=px)
    s = image_stats(im)
    assert s["bit_depth"] == (16 if replicate else 12)
    assert s["saturated_fraction"] == 0.2
    want = (0.2 * 4095 + 0.8 * 1024) / 4095
    assert abs(s["mean"] - want) < 1.0 / 4095  # bit replication is within one 12-bit step of v * 65535 / 4095
