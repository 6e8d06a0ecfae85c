"""``synth --rover m2020``: the Mars 2020 configuration (real static models + URDF, read at run time) renders a
downlink that validates, carries the M2020 models pointed through the URDF's RSM chain, and marks exactly."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.commands.synth import m2020_sim_rover
from scipctl.io.downlink import read_downlink
from scipctl.io.m2020_geometry import m2020_rover_config
from scipctl.sim.rover import scale_model
from scipctl.sim.build import scene_for
from scipctl.sim.scenarios import plan_run
from tests.io.real_data import real
from tests.sim.marks_check import count_exact_marks

runner = CliRunner()
SCALE = 0.125
SMALL_ENV = {"SCIPCTL_SYNTH_IMAGE_SCALE": str(SCALE), "SCIPCTL_SYNTH_SUPERSAMPLE": "1"}


@pytest.fixture(scope="module")
def m2020_run(tmp_path_factory):
    folder = real("12_")
    out = tmp_path_factory.mktemp("m2020")
    r = runner.invoke(app, ["synth", "--seed", "1", "--runs", "s1-straight", "--rover", "m2020", "--rover-dir", str(folder),
                            "-o", str(out), "--json"], env=SMALL_ENV)
    assert r.exit_code == 0, r.stderr
    return folder, out, json.loads(r.stdout)


def test_m2020_downlink_validates_and_carries_the_m2020_models_pointed_through_the_urdf(m2020_run):
    folder, out, summary = m2020_run
    dl = read_downlink(out / "paper-s1-straight.mcap")  # validates
    assert dl.rover_config.name.startswith("m2020")
    rc = m2020_rover_config(folder)
    assert len(dl.images) == summary["runs"][0]["images"] == 12
    for im in dl.images:
        spec = rc.spec(im.camera, im.eye)
        assert (im.width, im.height) == (round(spec.width * SCALE), round(spec.height * SCALE))
        assert im.pixels.shape == (im.height, im.width) and im.pixels.std() > 0
        pan, tilt = (im.mast.pan_rad, im.mast.tilt_rad) if im.mast is not None else (0.0, 0.0)
        want = scale_model(rc.camera_model(im.camera, im.eye, pan, tilt), SCALE)
        for k in ("C", "A", "H", "V"):
            assert np.allclose(getattr(im.camera_model, k), getattr(want, k), atol=1e-9), (im.product_id, k)
        assert im.camera_model.kind == spec.model.kind
        if im.camera == "hazcam":
            assert im.mast is None  # body-mounted
        # upright, as the rover takes them: the image's down is the world's down and the left eye on the left
        # (the mast images were upside down, the head tilted back over the top, before session 36)
        assert im.camera_model.v_axis[2] > 0.3, (im.product_id, im.camera_model.v_axis)
        other = next(o for o in dl.images if o.camera == im.camera and o.eye != im.eye and o.position == im.position)
        left, right = (im, other) if im.eye == "left" else (other, im)
        assert np.dot(right.camera_model.C - left.camera_model.C, left.camera_model.h_axis) > 0, im.product_id
    # Mastcam-Z stands in for the pancam, NAVL/NAVR for the navcams
    assert abs(rc.spec("pancam", "left").model.hs - dl.rover_config.spec("pancam", "left").model.hs / SCALE) \
        < 0.02 * rc.spec("pancam", "left").model.hs


def test_m2020_marks_are_the_exact_projection_of_the_true_targets(m2020_run):
    folder, out, _ = m2020_run
    dl = read_downlink(out / "paper-s1-straight.mcap")
    scene = scene_for(plan_run("paper", "s1-straight", 1, m2020_sim_rover(folder)))
    n = count_exact_marks(dl, scene)
    assert len(dl.targets) == 3 and n >= 3 * 6  # every target in both eyes of the 3 key pairs at least


def test_m2020_record_names_the_files_and_the_pancam_stand_in(m2020_run):
    folder, out, _ = m2020_run
    rec = json.loads((out / "paper-s1-straight.sim.json").read_text())
    files = {f["file"]: f["sha256"] for f in rec["rover"]["inputs"]}
    from scipctl.io.provenance import sha256_file

    assert files == {n: sha256_file(folder / n) for n in ("m2020-camera-models.json", "m2020.urdf")}
    assert "--rover m2020" in rec["written_by"]["regenerate"]
    assert any("Mastcam-Z" in n for n in rec["rover"]["notes"])
    # the URDF's wheel hubs: a 2.4 m x 2.4 m six-wheeler, so the approach corridors widened
    assert np.ptp(np.array(rec["rover"]["wheels_xy_m"])[:, 1]) > 2.0 and rec["rover"]["corridor_extra_m"] > 0.5


@pytest.mark.parametrize("args,field", [
    (["--rover", "curiosity"], "--rover"),
    (["--rover", "m2020", "--rover-dir", "/nonexistent/m2020"], "--rover-dir"),
    (["--rover-dir", "/tmp"], "--rover-dir"),
])
def test_bad_rover_exit_2_nothing_written(tmp_path, args, field):
    r = runner.invoke(app, ["synth", "-o", str(tmp_path / "o"), *args], env=SMALL_ENV)
    assert r.exit_code == 2 and field in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_m2020_folder_without_the_urdf_names_the_file(tmp_path):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "m2020-camera-models.json").write_text("[]")
    r = runner.invoke(app, ["synth", "-o", str(tmp_path / "o"), "--rover", "m2020", "--rover-dir", str(tmp_path / "m")],
                      env=SMALL_ENV)
    assert r.exit_code == 2 and "m2020.urdf" in r.stderr and not (tmp_path / "o").exists()


def test_scale_hook_checked_against_the_m2020_sizes(tmp_path):
    folder = real("12_")
    # 1280 x 960 navcams and 1648 x 1200 Mastcam-Z at 0.3: not whole
    r = runner.invoke(app, ["synth", "-o", str(tmp_path / "o"), "--rover", "m2020", "--rover-dir", str(folder)],
                      env={"SCIPCTL_SYNTH_IMAGE_SCALE": "0.3"})
    assert r.exit_code == 2 and "SCIPCTL_SYNTH_IMAGE_SCALE" in r.stderr and not (tmp_path / "o").exists()


def test_an_m2020_downlinks_sequence_uses_the_m2020_rules_and_its_final_pose_sees_the_target(m2020_run):
    """Issue #15: with the default rover's rules every Mars 2020 approach was refused (`hazcam-fov-final`: the
    target under the M2020 hazcams' view); without --rules the m2020 built-in is chosen from the downlink."""
    _, out, _ = m2020_run
    src = str(out / "paper-s1-straight.mcap")
    by_rules = {}
    for extra in ([], ["--rules", "default"]):
        r = runner.invoke(app, ["sequence", src, "--target", "t1", "--json", *extra])
        assert r.exit_code in (0, 1), r.stderr
        summary = json.loads(r.stdout)
        by_rules[summary["rules_file"]["file"]] = {c["rule"]: c["ok"] for c in summary["rules"]}
        if not extra:
            assert "rover configuration is 'm2020" in summary["rules_file"]["chosen_by"]
    assert by_rules["m2020 (scipctl/data/rules-m2020.yaml)"]["hazcam-fov-final"]
    assert not by_rules["default (scipctl/data/rules.yaml)"]["hazcam-fov-final"]
