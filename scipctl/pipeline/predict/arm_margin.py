"""The margin the final drive's error needs inside the arm workspace: the spread of the true target's position at
the final pose, from the Monte Carlo's own error model (:class:`~.params.UncertaintyParams`), linearised.

At the final pose the Monte Carlo (:func:`~.montecarlo.monte_carlo`) has the rover drive its estimate -- the
final stop's hazcam stereo re-estimate -- to where the plan put the designated point ``P`` (rover frame, at the
standoff ``s``, straight ahead). With the accumulated pose error ``(dxy, dtheta)`` at the final stop (the random
walk of :func:`~.montecarlo.sample_pose_errors`) and the stereo error ``n`` of the re-estimate (range noise
``r^2 sigma_d / (f b)`` along the hazcam's line of sight), the true target lands at, to first order,

    X_final = P - n - dtheta K dxy,   K = [[0, -1], [1, 0]]

(the correction is applied along the believed final heading, off the true one by ``dtheta``) and, to second order
in ``dtheta``, ``|X_final| = s (1 + dtheta^2)``: an outward bias ``s sigma_theta^2`` whose own spread is
``sqrt(2) s sigma_theta^2`` (``dtheta^2`` is ``sigma_theta^2`` times a chi-square of one degree of freedom). Along
the workspace's radius (the direction of ``P``)::

    sigma_r^2 = (sigma_range * los_radial)^2 + sigma_theta^2 sigma_xy^2 + 2 s^2 sigma_theta^4
    sigma_theta^2 = sum over legs of  sigma_yaw^2 + (yaw_error_rad_per_m * leg)^2
    sigma_xy^2    = sum over legs of  sigma_position^2 + (drive_error_frac * leg)^2     (per axis)

and the designated point needs ``margin = n_sigma * sigma_r + s sigma_theta^2`` inside the workspace's radial
limits. ``n_sigma`` is ``ApproachParams.arm_margin_sigmas`` (rules ``approach.arm_margin_sigmas``). The two
heading terms are not Gaussian (a product of normals, a chi-square): their tails are heavier than a normal's, so
the share of the Monte Carlo's samples beyond ``n_sigma`` is measured (``tests/pipeline/predict/test_arm_margin.py``)
rather than read off a normal table. The heading terms exist because the Monte Carlo applies the final correction
along the believed heading; if it changes, this model changes with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.kinematics import RoverConfig
from .params import UncertaintyParams


def stereo_range_sigma_m(rover_config: RoverConfig, camera: str, range_m: float, sigma_d_px: float) -> float:
    """1-sigma range error (m) of a stereo point at ``range_m`` from ``camera``'s pair: ``r^2 sigma_d / (f b)``
    (0 when the pair has no baseline)."""
    cam = rover_config.cameras[camera]
    b = float(np.linalg.norm(cam.right.model.C - cam.left.model.C))
    f = cam.left.model.hs
    if b <= 0:
        return 0.0
    return float(range_m * range_m * sigma_d_px / (f * b))


@dataclass(frozen=True)
class ArmMargin:
    """The final drive's error at the arm (m), for one planned approach (see the module docstring)."""

    sigma_stereo_m: float  # the final hazcam re-estimate's range error, along the workspace radius
    sigma_heading_m: float  # sigma_theta * sigma_xy: the correction applied along the believed heading
    bias_m: float  # s sigma_theta^2, outward
    sigma_bias_m: float  # sqrt(2) s sigma_theta^2: the spread of that second-order term
    n_sigma: float
    margin_m: float  # n_sigma * sigma_m + bias_m

    @property
    def sigma_m(self) -> float:
        return math.sqrt(self.sigma_stereo_m ** 2 + self.sigma_heading_m ** 2 + self.sigma_bias_m ** 2)

    def to_dict(self) -> dict:
        return dict(self.__dict__, sigma_m=self.sigma_m)


def arm_margin(legs_m, X_target_rover, rover_config: RoverConfig, up: UncertaintyParams, n_sigma: float,
               sigma_position_m: float, sigma_yaw_rad: float) -> ArmMargin:
    """The :class:`ArmMargin` of a plan whose legs (m, every stop after today's, the final leg last) are ``legs_m``
    and whose designated point sits at ``X_target_rover`` (3,) in the planned final rover frame.

    ``sigma_position_m``, ``sigma_yaw_rad``: the per-stop pose noise the Monte Carlo runs with
    (:func:`~.from_downlink.sigmas_for`). Without a hazcam pair the stereo term is 0 (the Monte Carlo then has
    no final re-estimate either).
    """
    X = np.asarray(X_target_rover, float).reshape(3)
    s = float(np.hypot(X[0], X[1]))
    u = X[:2] / s if s > 0 else np.array([1.0, 0.0])
    sig_stereo = 0.0
    if "hazcam" in rover_config.cameras:
        C = rover_config.camera_model("hazcam", "left").C
        los = X - C
        r = float(np.linalg.norm(los))
        sig_r = stereo_range_sigma_m(rover_config, "hazcam", r, up.disparity_sigma_px)
        sig_stereo = sig_r * abs(float(np.dot(los[:2] / r, u)))
    legs = np.asarray(legs_m, float).reshape(-1)
    var_theta = float(np.sum(sigma_yaw_rad ** 2 + (up.yaw_error_rad_per_m * legs) ** 2))
    var_xy = float(np.sum(sigma_position_m ** 2 + (up.drive_error_frac * legs) ** 2))
    sig_heading = math.sqrt(var_theta * var_xy)
    bias = s * var_theta
    sig_bias = math.sqrt(2.0) * bias
    sigma = math.sqrt(sig_stereo ** 2 + sig_heading ** 2 + sig_bias ** 2)
    return ArmMargin(float(sig_stereo), float(sig_heading), float(bias), float(sig_bias), float(n_sigma),
                     float(n_sigma * sigma + bias))
