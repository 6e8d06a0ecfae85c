"""The margin the final drive's error needs inside the arm workspace: the spread of the true target's position at
the final pose, from the Monte Carlo's own error model (:class:`~.params.UncertaintyParams`): the final
re-estimate's stereo error, averaged over the line of sight it lies along.

At the final pose the Monte Carlo (:func:`~.montecarlo.monte_carlo`) has the rover drive its estimate -- the
final stop's hazcam stereo re-estimate -- to where the plan put the designated point ``P`` (rover frame, at the
standoff ``s``, straight ahead). The correction is commanded in the rover's body frame, so it moves along the
rover's true final heading (issue #15): the pose error ``(dxy, dtheta)`` accumulated by the final stop (the random
walk of :func:`~.montecarlo.sample_pose_errors`) cancels exactly, since the estimate was measured from that same
true pose. What remains is the re-estimate's stereo error ``n`` (range noise ``r^2 sigma_d / (f b)`` along the
hazcam's line of sight, rotated into the true final frame)::

    X_final = P - n          (exact in the Monte Carlo, not only to first order)

so along the workspace's radius (the direction of ``P``, unit ``u``) the error has no bias and::

    sigma_r^2 = sigma_range^2 * E[ (los_h . u)^2 / |los|^2 ]

where ``los`` runs from the hazcam to the target as seen from the true final pose *before* the correction, i.e.
at ``P - dxy - dtheta K P`` (``K = [[0, -1], [1, 0]]``): the pose error no longer moves the arm point, but it
still tilts the line of sight the re-estimate's error lies along. The expectation is over that spread (radial
variance ``sigma_xy^2``, lateral ``sigma_xy^2 + s^2 sigma_theta^2``, Gauss-Hermite quadrature) with::

    sigma_theta^2 = sum over legs of  sigma_yaw^2 + (yaw_error_rad_per_m * leg)^2
    sigma_xy^2    = sum over legs of  sigma_position^2 + (drive_error_frac * leg)^2     (per axis)

(on a straight 9 m approach the share's spread raises sigma_r by 10 % at a 0.8 m standoff and lowers it by 3 % at
1.0 m against the planned line of sight's). The designated point needs ``margin = n_sigma * sigma_r`` inside the
workspace's radial limits.
``n_sigma`` is ``ApproachParams.arm_margin_sigmas`` (rules ``approach.arm_margin_sigmas``); the Monte Carlo
comparison is ``tests/pipeline/predict/test_arm_margin.py``.

Without a hazcam pair the final stop re-measures nothing and the estimate is carried from the last stop that did
stereo; then the relative pose error between that stop and the final one remains: its position part (per axis
``sigma_xy^2 = sum over those legs of sigma_position^2 + (drive_error_frac * leg)^2``) along the radius, its heading
part perpendicular to ``P`` to first order. Not knowing that stop here, the model sums every leg (an upper bound of
the position part) and ignores the earlier stop's stereo error; that case is not compared with the Monte Carlo
(whose views all fail without a hazcam).
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


_GH_NODES = 15  # Gauss-Hermite nodes per axis for the line of sight's radial share


@dataclass(frozen=True)
class ArmMargin:
    """The final drive's error at the arm (m), for one planned approach (see the module docstring)."""

    sigma_stereo_m: float  # the final hazcam re-estimate's range error, along the workspace radius
    # without a hazcam: the relative pose error since the last stereo stop (every leg's, an upper bound); else 0
    sigma_pose_m: float
    n_sigma: float
    margin_m: float  # n_sigma * sigma_m

    @property
    def sigma_m(self) -> float:
        return math.sqrt(self.sigma_stereo_m ** 2 + self.sigma_pose_m ** 2)

    def to_dict(self) -> dict:
        return dict(self.__dict__, sigma_m=self.sigma_m)


def arm_margin(legs_m, X_target_rover, rover_config: RoverConfig, up: UncertaintyParams, n_sigma: float,
               sigma_position_m: float, sigma_yaw_rad: float) -> ArmMargin:
    """The :class:`ArmMargin` of a plan whose legs (m, every stop after today's, the final leg last) are ``legs_m``
    and whose designated point sits at ``X_target_rover`` (3,) in the planned final rover frame.

    ``sigma_position_m``, ``sigma_yaw_rad``: the per-stop pose noise the Monte Carlo runs with
    (:func:`~.from_downlink.sigmas_for`). With a hazcam pair only the final re-estimate's stereo error counts
    (the pose error cancels: module docstring); the pose error enters only through the line of sight that error
    lies along. Without one the position random walk over every leg is the (upper-bound) margin.
    """
    X = np.asarray(X_target_rover, float).reshape(3)
    s = float(np.hypot(X[0], X[1]))
    u = X[:2] / s if s > 0 else np.array([1.0, 0.0])
    legs = np.asarray(legs_m, float).reshape(-1)
    var_theta = float(np.sum(sigma_yaw_rad ** 2 + (up.yaw_error_rad_per_m * legs) ** 2))
    var_xy = float(np.sum(sigma_position_m ** 2 + (up.drive_error_frac * legs) ** 2))
    sig_stereo = 0.0
    sig_pose = 0.0
    if "hazcam" in rover_config.cameras:
        C = rover_config.camera_model("hazcam", "left").C
        los = X - C
        r = float(np.linalg.norm(los))
        sig_r = stereo_range_sigma_m(rover_config, "hazcam", r, up.disparity_sigma_px)
        # the re-estimate is measured from the true final pose, before the correction: the target then sits at
        # P - dxy - dtheta K P, and the line of sight's radial share moves with it; average it over that spread
        # (Gauss-Hermite, radial variance var_xy, lateral var_xy + s^2 var_theta)
        sd_rad = math.sqrt(var_xy)
        sd_lat = math.sqrt(var_xy + s * s * var_theta)
        z, w = np.polynomial.hermite_e.hermegauss(_GH_NODES)
        w = w / w.sum()
        a, b = np.meshgrid(z * sd_rad, z * sd_lat, indexing="ij")
        v = np.array([-u[1], u[0]])
        Y = X[None, :2] + a.reshape(-1, 1) * u[None] + b.reshape(-1, 1) * v[None]
        los = np.c_[Y, np.full(len(Y), X[2])] - C[None]
        share2 = (los[:, :2] @ u) ** 2 / np.sum(los * los, axis=1)
        sig_stereo = sig_r * math.sqrt(float(np.outer(w, w).reshape(-1) @ share2))
    else:
        sig_pose = math.sqrt(var_xy)
    sigma = math.hypot(sig_stereo, sig_pose)
    return ArmMargin(float(sig_stereo), float(sig_pose), float(n_sigma), float(n_sigma * sigma))
