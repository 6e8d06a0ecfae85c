"""scipctl/pipeline/operator_sigmas.py: the operator's pose-error sigmas as prediction parameters."""

import math

import pytest

from scipctl.errors import InputError
from scipctl.pipeline.operator_sigmas import uncertainty_params


def test_sigmas_reach_the_uncertainty_params():
    u = uncertainty_params(0.05, 2.0).uncertainty
    assert u.sigma_position_m == 0.05 and math.isclose(u.sigma_yaw_rad, math.radians(2.0))


def test_none_means_from_the_downlink():
    u = uncertainty_params().uncertainty
    assert u.sigma_position_m is None and u.sigma_yaw_rad is None


@pytest.mark.parametrize("pos, yaw, option", [(-1.0, None, "--sigma-position-m"), (0.0, None, "--sigma-position-m"),
                                              (None, float("nan"), "--sigma-yaw-deg"), (None, float("inf"), "--sigma-yaw-deg")])
def test_not_positive_finite_is_an_input_error_naming_the_option(pos, yaw, option):
    with pytest.raises(InputError) as e:
        uncertainty_params(pos, yaw)
    assert e.value.product == option
