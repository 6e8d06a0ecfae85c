"""docs/scripts/trust_render.py --stale: the option's spec -> the ErrorSettings fields, and its refusals.

What a stale calibration does to the rendered geometry is tested in tests/sim/test_errors.py
(test_stale_calibration_biases_stereo_range)."""

import math

import pytest

from scipctl.sim.errors import ErrorSettings
from tests import doc_scripts


@pytest.fixture(scope="module")
def tr():
    return doc_scripts.load("trust_render")


def test_a_spec_sets_the_stale_fields_and_they_apply_to_error_settings(tr):
    from dataclasses import replace

    got = tr.stale_settings("navcam:1.01")
    assert got == {"stale_camera": "navcam", "stale_baseline_scale": 1.01, "stale_focal_scale": 1.0}
    assert tr.stale_settings("hazcam:0.995:1.002")["stale_focal_scale"] == 1.002
    e = replace(ErrorSettings(), **got)
    assert e.stale_camera == "navcam" and math.isclose(e.stale_baseline_scale, 1.01)


@pytest.mark.parametrize("spec", ["navcam", "mastcam:1.01", "navcam:x", "navcam:1.01:1:2", "hazcam:3", "navcam:0.4"])
def test_a_malformed_spec_is_refused_naming_the_option(tr, spec):
    with pytest.raises(ValueError, match="--stale"):
        tr.stale_settings(spec)


def test_the_command_line_refuses_it_with_exit_2(tr):
    with pytest.raises(SystemExit) as ex:
        tr.main(["default", "1", "s1-straight", "/nonexistent-out", "--stale", "navcam"])
    assert ex.value.code == 2
