"""`scipctl designate` on a bundled sample sol (copied: designations are saved beside the input)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import read_downlink

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
runner = CliRunner()


@pytest.fixture(scope="module")
def dl(sol):
    return read_downlink(sol)


def _first_pancam(dl):
    return min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)


def _right_model_used(dl, rec):
    """The right model the command's stereo read: the downlinked one turned by the self-calibration it records."""
    from scipctl.core.stereo_selfcal import rotated_model

    (fit,) = rec["provenance"]["stereo_selfcal"]  # designate fits the one pair it reads
    assert fit["left"] == rec["product_id"]
    right = dl.product(fit["right"])
    return rotated_model(right.camera_model, np.asarray(fit["rotvec_rad"])) if fit["applied"] else right.camera_model


def test_designate_a_marked_target(sol, dl):
    left = _first_pancam(dl)
    t = next(t for t in dl.targets if t.kind == "point")
    mk = t.mark_in(left.product_id)
    r = runner.invoke(app, ["designate", str(sol), "--product", left.product_id, "--pixel", f"{mk.u},{mk.v}",
                            "--id", "rock1", "--json"])
    assert r.exit_code == 0, r.output
    rec = json.loads(r.stdout)
    assert rec["id"] == "rock1" and rec["ok"]
    # the stereo match against the ideal one: the exact left and right marks triangulated with the models the
    # command used (the downlinked left, the self-calibrated right; they carry the simulated mast-calibration
    # error, which no matcher can see)
    from scipctl.core.triangulation import triangulate_rays

    right = dl.stereo_pair(left)
    mr = t.mark_in(right.product_id)
    right_model = _right_model_used(dl, rec)
    (o1, d1), (o2, d2) = left.camera_model.unproject(np.array([mk.u, mk.v])), right_model.unproject(np.array([mr.u, mr.v]))
    X_ideal = np.asarray(triangulate_rays(o1, d1, o2, d2)[0]).reshape(3)
    X = np.asarray(rec["xyz_rover_m"])
    ray = (X_ideal - left.camera_model.C) / np.linalg.norm(X_ideal - left.camera_model.C)
    e = X - X_ideal
    along, lateral = float(e @ ray), float(np.linalg.norm(e - (e @ ray) * ray))
    assert abs(rec["range_m"] - np.linalg.norm(X - left.camera_model.C)) < 1e-6
    assert lateral < 0.005, lateral
    assert abs(along) < 3 * rec["range_sigma_m"], (along, rec["range_sigma_m"])
    # and the truth, in the rover frame, is within the calibration error (1 deg at ~10 m ~ 0.17 m)
    tp = dl.truth_for(left.product_id)
    X_true = tp.pose.T_site_rover.inverse().apply(np.asarray(dl.truth_target(t.id).xyz_site_m))
    assert np.linalg.norm(X - X_true) < 0.5
    assert rec["range_sigma_m"] > 0
    assert rec["epipolar_offset_px"] is not None
    assert rec["provenance"]["version"]
    saved = json.loads((sol.parent / (sol.name + ".scipctl") / "targets.json").read_text())
    assert [t["id"] for t in saved["targets"]] == ["rock1"]


@pytest.mark.parametrize("selfcal", [True, False])
def test_epipolar_offset_reports_the_injected_vibration(sol, dl, selfcal):
    """The right pancam's true orientation is perturbed by the simulator: the measured offset from the epipolar
    line is the offset of the true right mark from the epipolar curve of the models used: with the downlinked
    models (--no-stereo-selfcal) it is the vibration's; self-calibrated (the default) it is what is left of it."""
    left = _first_pancam(dl)
    right = dl.stereo_pair(left)
    t = next(t for t in dl.targets if t.kind == "point")
    ml, mr = t.mark_in(left.product_id), t.mark_in(right.product_id)
    r = runner.invoke(app, ["designate", str(sol), "--product", left.product_id, "--pixel", f"{ml.u},{ml.v}", "--json"]
                      + ([] if selfcal else ["--no-stereo-selfcal"]))
    rec = json.loads(r.stdout)
    if selfcal:
        right_model = _right_model_used(dl, rec)
    else:
        assert rec["provenance"]["stereo_selfcal"] is False
        right_model = right.camera_model
    o, d = left.camera_model.unproject(np.array([ml.u, ml.v]))
    curve = right_model.project(o[None] + np.linspace(2, 40, 2000)[:, None] * d[None])
    dist = np.min(np.linalg.norm(curve - [mr.u, mr.v], axis=1))
    assert abs(abs(rec["epipolar_offset_px"]) - dist) < 0.5
    assert np.linalg.norm(np.asarray(rec["uv_right"]) - [mr.u, mr.v]) < 1.0


@pytest.mark.parametrize("args,field", [
    (["--pixel", "5000,10"], "pixel"),
    (["--pixel", "abc"], "pixel"),
    (["--pixel", "nan,3"], "pixel"),
    (["--pixel", "500,500", "--band-px", "inf"], "band_px"),  # was exit 3 (a ValueError from point_stereo)
    (["--pixel", "500,500", "--band-px", "0"], "band_px"),
])
def test_bad_pixels_exit_2(sol, dl, args, field):
    left = _first_pancam(dl)
    r = runner.invoke(app, ["designate", str(sol), "--product", left.product_id] + args)
    assert r.exit_code == 2
    assert field in r.stderr and "Traceback" not in r.stderr


def test_right_eye_and_unknown_product_exit_2(sol, dl):
    right = dl.stereo_pair(_first_pancam(dl))
    r = runner.invoke(app, ["designate", str(sol), "--product", right.product_id, "--pixel", "500,500"])
    assert r.exit_code == 2 and "eye" in r.stderr
    r = runner.invoke(app, ["designate", str(sol), "--product", "nope", "--pixel", "500,500"])
    assert r.exit_code == 2 and "nope" in r.stderr
    r = runner.invoke(app, ["designate", str(sol), "--pixel", "500,500"])
    assert r.exit_code == 2


def test_no_reliable_match_exits_1(tmp_path):
    """A textureless (uniform) pair: no stereo match -> exit code 1, one line, nothing saved."""
    from scipctl.io.downlink import write_downlink
    from scipctl.io.images import encode_png
    from tests.io.builders import make_small_downlink

    small = make_small_downlink(width=160, height=120)
    for im in small.images:
        im.png = encode_png(np.full((im.height, im.width), 90, np.uint8))
        im._pixels = None
    p = write_downlink(small, tmp_path / "flat.mcap", container="mcap")
    left = next(im for im in small.images if im.eye == "left" and im.camera == "pancam")
    r = subprocess.run([sys.executable, "-m", "scipctl.cli", "designate", str(p), "--product", left.product_id,
                        "--pixel", "80,60"], capture_output=True, text=True)
    assert r.returncode == 1, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "flat.mcap.scipctl" / "targets.json").exists()


def test_camera_option_picks_latest_left_image(sol, dl):
    t = next(t for t in dl.targets if t.kind == "point")
    latest = max((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = t.mark_in(latest.product_id)
    r = runner.invoke(app, ["designate", str(sol), "--camera", "pancam", "--pixel", f"{mk.u},{mk.v}", "--json"])
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["product_id"] == latest.product_id


def test_a_vetoed_designation_exits_1_saying_why_and_is_saved(tmp_path):
    """The low-texture veto through the command (the exact slab scene at 5 % contrast, as
    tests/pipeline/test_designation_trust.py): exit 1, one line that names the reason instead of a GO-sized P, and
    the record saved with the veto among its warnings."""
    from scipctl.io.downlink import write_downlink
    from tests.pipeline import scene as S
    from tests.pipeline.broken_downlinks import _swap, encode_pixels, with_pixels

    _, dl = S.cached("slab")
    left = dl.product("pancam_left_1_0")
    faint = {p.product_id: with_pixels(p, 120.0 + (p.pixels.astype(float) - p.pixels.mean()) * 0.05)
             for p in (left, dl.stereo_pair(left))}
    path = write_downlink(encode_pixels(_swap(dl, faint)), tmp_path / "faint.mcap", container="mcap")
    mk = dl.target("t_flat").mark_in(left.product_id)
    r = subprocess.run([sys.executable, "-m", "scipctl.cli", "designate", str(path), "--product", left.product_id,
                        "--pixel", f"{mk.u},{mk.v}", "--id", "f1"], capture_output=True, text=True)
    assert r.returncode == 1, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert "NO-GO" in last and "texture" in last and "Traceback" not in r.stderr
    saved = json.loads((tmp_path / "faint.mcap.scipctl" / "targets.json").read_text())
    rec = next(t for t in saved["targets"] if t["id"] == "f1")
    assert rec["go"] is False and any(w.startswith("NO-GO whatever p_ok") for w in rec["warnings"])


@pytest.mark.parametrize("bad_id", ["", " ", "t 1", "../x", "a\nb", "-x", "x" * 65])
def test_a_bad_target_id_exits_2_and_saves_nothing(tmp_path, dl, bad_id):
    """Ids name records, sequence headers and options: an empty id used to be saved and then broke every later
    command on the workspace; one with a line break split the SeqN header."""
    sol = tmp_path / SAMPLE.name
    sol.write_bytes(SAMPLE.read_bytes())
    r = runner.invoke(app, ["designate", str(sol), "--camera", "pancam", "--pixel", "512,380", "--id", bad_id])
    assert r.exit_code == 2, r.output
    assert r.stderr.startswith("scipctl: error: --id: id: ") and r.stderr.count("\n") == 1
    assert not (tmp_path / (SAMPLE.name + ".scipctl") / "targets.json").exists()


def test_an_existing_or_marked_id_is_refused_unless_replace(tmp_path, dl):
    """Reusing an id used to replace the earlier target silently, a marked one too (sequence --target t2 then
    planned for the new pixel, not the marked rock)."""
    sol = tmp_path / SAMPLE.name
    sol.write_bytes(SAMPLE.read_bytes())
    targets = tmp_path / (SAMPLE.name + ".scipctl") / "targets.json"
    left = _first_pancam(dl)
    t = next(t for t in dl.targets if t.kind == "point")
    mk = t.mark_in(left.product_id)
    base = ["designate", str(sol), "--product", left.product_id, "--pixel", f"{mk.u},{mk.v}", "--json"]
    assert runner.invoke(app, base + ["--id", "zz"]).exit_code == 0
    before = targets.read_bytes()
    r = runner.invoke(app, base + ["--id", "zz"])
    assert r.exit_code == 2 and "already a designated target" in r.stderr and "--replace" in r.stderr
    r = runner.invoke(app, base + ["--id", t.id])
    assert r.exit_code == 2 and "marked target" in r.stderr
    assert targets.read_bytes() == before and r.stdout == ""
    r = runner.invoke(app, ["designate", str(sol), "--product", left.product_id, "--pixel",
                            f"{mk.u + 3},{mk.v}", "--id", "zz", "--replace", "--json"])
    assert r.exit_code == 0, r.stderr
    saved = json.loads(targets.read_text())["targets"]
    assert [s["id"] for s in saved] == ["zz"] and saved[0]["pixel_uv"][0] == pytest.approx(mk.u + 3)


def test_product_and_camera_together_exit_2(sol, dl):
    left = _first_pancam(dl)
    r = runner.invoke(app, ["designate", str(sol), "--product", left.product_id, "--camera", "pancam",
                            "--pixel", "500,500"])
    assert r.exit_code == 2 and "not both" in r.stderr


def test_a_failed_match_prints_strict_json(tmp_path):
    """Exit 1 at a corner pixel (the window mostly outside the image): the record on stdout is strict JSON, its
    right-eye pixel null (it printed [NaN, NaN])."""
    sol = tmp_path / SAMPLE.name
    sol.write_bytes(SAMPLE.read_bytes())
    r = runner.invoke(app, ["designate", str(sol), "--camera", "pancam", "--pixel", "1,1", "--json"])
    assert r.exit_code == 1, r.output

    def refuse(c):
        raise ValueError(c)

    rec = json.loads(r.stdout, parse_constant=refuse)
    assert rec["ok"] is False and rec["saved_to"] is None and rec["uv_right"] in (None, [None, None])
    # the keys of a match's document are all there (a script reading doc["go"] got a KeyError exactly here)
    assert rec["go"] is False
    for key in ("xyz_site_m", "xyz_rover_m", "range_m", "range_sigma_m", "p_ok", "pose", "window_range_gap_pct"):
        assert key in rec and rec[key] is None, key


def test_two_designates_at_once_keep_both_targets(tmp_path, dl):
    """Two processes designating on one workspace at the same time: both targets are saved (before the products'
    lock one was lost in every trial, both runs saying they saved theirs)."""
    ws = tmp_path / "ws"
    assert runner.invoke(app, ["ingest", str(SAMPLE), "-o", str(ws)]).exit_code == 0
    left = _first_pancam(dl)
    mk = next(t for t in dl.targets if t.kind == "point").mark_in(left.product_id)
    cmd = [sys.executable, "-m", "scipctl.cli", "designate", str(ws), "--product", left.product_id]
    procs = [subprocess.Popen(cmd + ["--pixel", f"{mk.u + du},{mk.v}", "--id", i], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE) for du, i in ((0, "a"), (4, "b"))]
    out = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], out
    saved = json.loads((ws / "scipctl" / "targets.json").read_text())["targets"]
    assert sorted(t["id"] for t in saved) == ["a", "b"]


@pytest.mark.parametrize("args", [["--product", "", "--camera", "pancam"], ["--camera", " ", "--product", "x"],
                                  ["--product", ""]])
def test_an_empty_product_or_camera_exits_2_and_saves_nothing(tmp_path, args):
    # `--product "$P" --camera pancam` with P unset designated from the pancam (exit 0, saved), as if the
    # empty --product had not been given
    src = tmp_path / SAMPLE.name
    src.write_bytes(SAMPLE.read_bytes())
    r = runner.invoke(app, ["designate", str(src), *args, "--pixel", "512.25,380.5"])
    assert r.exit_code == 2, r.stderr
    assert r.stderr.strip().splitlines() == [f"scipctl: error: {args[0]}: {args[0][2:]}: empty: give a value, or leave "
                                             "the option out"]
    assert not Path(str(src) + ".scipctl", "targets.json").exists()
