"""scipctl/commands/params.py: each command's parameters built from its options, options checked first."""

import math

import pytest

from scipctl.commands import params as C
from scipctl.core.handoff import HandoffParams
from scipctl.core.point_stereo import PointStereoParams
from scipctl.errors import InputError
from scipctl.pipeline.predict import PredictParams
from scipctl.pipeline.report_data import ReportParams


def test_defaults_are_the_algorithms_defaults():
    assert C.designation_params() == PointStereoParams()
    assert C.handoff_params() == HandoffParams()
    assert C.predict_params() == PredictParams()
    assert C.report_params() == ReportParams()


def test_options_reach_the_params():
    assert C.designation_params(5.0) == PointStereoParams.with_band(5.0)
    assert C.handoff_params(fast=True).dense_downsample == 2
    assert C.success_threshold(4) == 4.0
    u = C.predict_params(0.05, 2.0).uncertainty
    assert (u.sigma_position_m, u.sigma_yaw_rad) == (0.05, math.radians(2.0))
    r = C.report_params(0.05, 2.0)
    assert (r.sigma_position_m, r.sigma_yaw_rad) == (0.05, math.radians(2.0))


@pytest.mark.parametrize("call, start", [
    (lambda: C.designation_params(0.0), "--band-px: band_px: must be a positive finite number, got 0.0"),
    (lambda: C.designation_params(float("nan")), "--band-px: band_px: must be a positive"),
    (lambda: C.success_threshold(float("inf")), "--success-px: success_px: must be a positive finite number"),
    (lambda: C.predict_params(-1.0, None), "--sigma-position-m: sigma_position_m: must be a positive number"),
    (lambda: C.report_params(None, 0.0), "--sigma-yaw-deg: sigma_yaw_deg: must be a positive number"),
])
def test_a_bad_option_is_one_input_error_naming_it(call, start):
    with pytest.raises(InputError) as e:
        call()
    assert str(e.value).startswith(start) and "\n" not in str(e.value)


@pytest.mark.parametrize("params, start", [
    (ReportParams(chip_half_px=0), "ReportParams.chip_half_px: must be an integer >= 1, got 0"),
    (ReportParams(n_mc_samples=1.5), "ReportParams.n_mc_samples: must be an integer >= 1"),
    (ReportParams(sigma_yaw_rad=-0.1), "ReportParams.sigma_yaw_rad: must be a number >= 0 or None"),
    (ReportParams(calibration_stereo=PointStereoParams(other_window_px=1)), "PointStereoParams.window_px"),
])
def test_report_params_check_names_the_field(params, start):
    with pytest.raises(ValueError) as e:
        params.check()
    assert str(e.value).startswith(start), str(e.value)


def test_the_report_calibration_stereo_keeps_its_own_band_and_window():
    """The calibration-health offsets have always used a 15 px pancam window (11 otherwise) and a 6 px band for
    cameras other than pancam/navcam/hazcam, unlike the designation's 21 px windows and 4 px fallback band."""
    cal, des = ReportParams().calibration_stereo, PointStereoParams()
    assert [cal.window(c) for c in ("pancam", "navcam", "hazcam")] == [15, 11, 11]
    assert [cal.band(c) for c in ("pancam", "navcam", "hazcam", "mastcamz")] == [6.0, 3.0, 3.0, 6.0]
    assert [des.band(c) for c in ("pancam", "navcam", "hazcam", "mastcamz")] == [6.0, 3.0, 3.0, 4.0]
