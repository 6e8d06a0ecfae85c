"""docs/scripts/sun_change_render.py: the sun moved for the designation stop only, everything else the control's,
and the control the same bytes as ``scipctl synth``."""

import math

import numpy as np
import pytest

from tests import doc_scripts


@pytest.fixture(scope="module")
def sc():
    return doc_scripts.load("sun_change_render")


def _az_el_deg(s):
    return math.degrees(math.atan2(s[1], s[0])), math.degrees(math.asin(-s[2]))


def test_the_shift_moves_azimuth_and_elevation_by_the_stated_angles(sc):
    sun = np.array([math.cos(math.radians(40)) * math.cos(math.radians(20)),
                    math.cos(math.radians(40)) * math.sin(math.radians(20)), -math.sin(math.radians(40))])
    got = sc.shifted_sun(sun, 30.0, -10.0)
    az, el = _az_el_deg(got)
    # exact trigonometry: only rounding separates them (1e-9 deg is ~1e5 float64 ulps of margin)
    assert abs(np.linalg.norm(got) - 1.0) < 1e-12
    assert abs(az - 50.0) < 1e-9 and abs(el - 30.0) < 1e-9
    assert np.allclose(sc.shifted_sun(sun, 0.0, 0.0), sun, atol=1e-12)
    # the elevation is kept above the horizon
    assert abs(_az_el_deg(sc.shifted_sun(sun, 0.0, -60.0))[1] - sc.MIN_ELEVATION_DEG) < 1e-9


@pytest.mark.parametrize("spec", ["30", "a:b", "30:-10:1", "200:0", "0:70", "nan:0"])
def test_a_malformed_shift_is_refused_naming_the_option(sc, spec):
    with pytest.raises(ValueError, match="--shift"):
        sc.parse_shift(spec)


def test_the_command_line_refuses_a_bad_shift_or_family_with_exit_2(sc, tmp_path):
    for argv in (["default", "1", "s1-straight", str(tmp_path / "o"), "--shift", "30"],
                 ["no-such-family", "1", "s1-straight", str(tmp_path / "o")]):
        with pytest.raises(SystemExit) as ex:
            sc.main(argv)
        assert ex.value.code == 2
    assert not (tmp_path / "o").exists()


def test_control_is_synth_and_only_the_designation_images_change(sc, tmp_path, capsys):
    from scipctl.io.downlink import read_downlink
    from scipctl.io.images import decode_png
    from scipctl.sim.build import build_run

    assert sc.main(["default", "7", "s1-straight", str(tmp_path), "--shift", "40:-10", "--image-scale", "0.125"]) == 0
    ctrl = read_downlink(tmp_path / "control" / "paper-s1-straight.mcap")
    moved = read_downlink(tmp_path / sc.shift_name(40.0, -10.0) / "paper-s1-straight.mcap")
    ref = build_run("paper", "s1-straight", 7, image_scale=0.125, family="default")  # what synth writes
    ref_png = {im.product_id: im.png for im in ref.downlink.images}
    changed = []
    for a, b in zip(ctrl.images, moved.images):
        assert a.product_id == b.product_id and a.png == ref_png[a.product_id]
        assert np.array_equal(a.camera_model.C, b.camera_model.C)
        assert np.array_equal(a.pose.T_site_rover.R, b.pose.T_site_rover.R) and np.array_equal(a.pose.T_site_rover.t, b.pose.T_site_rover.t)
        if a.png != b.png:
            changed.append(a.product_id)
            # the same scene under another sun: a different picture of the same ground
            pa, pb = decode_png(a.png, a.product_id).astype(float), decode_png(b.png, b.product_id).astype(float)
            assert np.mean(np.abs(pa - pb)) > 1.0
    assert sorted(changed) == ["s1-straight-pan10-pancam-L", "s1-straight-pan10-pancam-R"]
    assert [t.id for t in ctrl.targets] == [t.id for t in moved.targets]
