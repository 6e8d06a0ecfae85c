"""Parameters of the pre-uplink prediction: the arm workspace and rover footprint models, the approach
planning (with the field-of-view margins), the pose-error model and the prediction as a whole (with the
criteria a tracked pixel is judged by), each with ``check()``."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ...core.handoff import HandoffParams
from ..chain import ChainParams

def _check_number(owner: str, name: str, v, lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False,
                  integer: bool = False, none_ok: bool = False, lo_name: str = "") -> None:
    """Raise ValueError ``"owner.name: must be ..., got v"`` unless ``v`` is a finite number in range
    (``lo_name``: the field the lower bound comes from, for the message)."""
    if v is None and none_ok:
        return
    kind = "an integer" if integer else "a number"
    ok = (isinstance(v, (int, np.integer)) if integer else isinstance(v, (int, float, np.number))) \
        and not isinstance(v, bool) and math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi
    if not ok:
        rng = []
        if lo > -math.inf:
            rng.append(f"{'>' if lo_open else '>='} " + (f"{lo_name} ({lo:g})" if lo_name else f"{lo:g}"))
        if hi < math.inf:
            rng.append(f"<= {hi:g}")
        what = " ".join([kind] + [" and ".join(rng)] * bool(rng) + ["or None"] * none_ok)
        raise ValueError(f"{owner}.{name}: must be {what}, got {v!r}")


@dataclass(frozen=True)
class ArmWorkspace:
    """Where the arm can place its instrument, in the rover frame at the final pose (a simple documented model).

    The target's horizontal position ``(x forward, y right)`` must satisfy
    ``r_min_m <= hypot(x, y) <= r_max_m``, ``x > 0`` and ``|y| <= half_width_m``
    (an annulus sector ahead of the rover origin).
    """

    r_min_m: float = 0.6
    r_max_m: float = 1.0
    half_width_m: float = 0.4

    def check(self) -> "ArmWorkspace":
        """Raise ValueError naming the first bad field; return self."""
        _check_number("ArmWorkspace", "r_min_m", self.r_min_m, 0.0)
        _check_number("ArmWorkspace", "r_max_m", self.r_max_m, self.r_min_m, lo_open=True, lo_name="r_min_m")
        _check_number("ArmWorkspace", "half_width_m", self.half_width_m, 0.0, lo_open=True)
        return self

    @property
    def centre_m(self) -> float:
        return 0.5 * (self.r_min_m + self.r_max_m)

    def contains(self, xy_rover) -> np.ndarray:
        """``xy_rover`` (..., 2) horizontal rover-frame positions -> (...,) bool."""
        p = np.asarray(xy_rover, float)
        if p.shape[-1] != 2:
            raise ValueError(f"xy_rover: expected (..., 2), got {p.shape}")
        r = np.hypot(p[..., 0], p[..., 1])
        return (r >= self.r_min_m) & (r <= self.r_max_m) & (p[..., 0] > 0) & (np.abs(p[..., 1]) <= self.half_width_m)


@dataclass(frozen=True)
class RoverBody:
    """The rover's footprint in its own frame: the rectangle ``rear_m <= x <= front_m``, ``|y| <= half_width_m``."""

    front_m: float = 0.5
    rear_m: float = -0.5
    half_width_m: float = 0.4

    def check(self) -> "RoverBody":
        """Raise ValueError naming the first bad field; return self."""
        _check_number("RoverBody", "front_m", self.front_m)
        _check_number("RoverBody", "rear_m", self.rear_m)
        if not self.rear_m < self.front_m:
            raise ValueError(f"RoverBody.rear_m: must be < front_m ({self.front_m:g}), got {self.rear_m!r}")
        _check_number("RoverBody", "half_width_m", self.half_width_m, 0.0, lo_open=True)
        return self

    def distance(self, xy_rover) -> np.ndarray:
        """Horizontal distance (m) of rover-frame points ``(..., 2)`` from the footprint (0 inside)."""
        p = np.asarray(xy_rover, float)
        if p.shape[-1] != 2:
            raise ValueError(f"xy_rover: expected (..., 2), got {p.shape}")
        dx = np.maximum(np.maximum(self.rear_m - p[..., 0], p[..., 0] - self.front_m), 0.0)
        dy = np.maximum(np.abs(p[..., 1]) - self.half_width_m, 0.0)
        return np.hypot(dx, dy)

    def corners(self) -> np.ndarray:
        """(4, 2) footprint corners, rover frame."""
        return np.array([[self.front_m, -self.half_width_m], [self.front_m, self.half_width_m],
                         [self.rear_m, self.half_width_m], [self.rear_m, -self.half_width_m]])


@dataclass(frozen=True)
class ApproachParams:
    """How the approach is planned (distances are horizontal, rover origin to target)."""

    stop_fraction: float = 0.15  # a stop after every ~15 % of the remaining distance
    min_leg_m: float = 0.3
    merge_m: float = 0.25  # regular stops this close to a special stop are dropped
    pancam_handoff_m: float = 4.5
    hazcam_handoff_m: float = 2.0
    hazcam_stops_m: tuple = (1.4,)
    standoff_m: Optional[float] = None  # final distance; None: searched in the arm workspace, its centre first
    standoff_step_m: float = 0.05  # the standoff search's step (plan_approach), when standoff_m is None
    # the searched standoff keeps the designated point this many sigmas of the final drive's error (arm_margin.py)
    # inside the arm workspace when a candidate can; 0: the workspace's own edges
    arm_margin_sigmas: float = 2.0
    detour_bearings_rad: tuple = tuple(np.deg2rad([0.0, 15.0, -15.0, 30.0, -30.0, 45.0, -45.0]).tolist())
    path_step_m: float = 0.05
    turn_step_rad: float = math.radians(10.0)
    rock_height_m: float = 0.15  # rocks at least this tall (above the local ground) are obstacles
    rock_cell_m: float = 0.05
    ground_window_m: float = 1.0
    rock_keep_out_m: float = 0.15
    target_keep_out_m: float = 0.25
    arm: ArmWorkspace = field(default_factory=ArmWorkspace)
    body: RoverBody = field(default_factory=RoverBody)
    # a target is in view when its pixel is at least this far inside the image (px, per camera; other cameras:
    # other_fov_margin_px); the planner, the Monte Carlo and the chain simulation all judge views by it
    fov_margin_px: dict = field(default_factory=lambda: {"pancam": 24, "navcam": 20, "hazcam": 20})
    other_fov_margin_px: int = 20

    def check(self) -> "ApproachParams":
        """Raise ValueError naming the first bad field; return self."""
        c = "ApproachParams"
        _check_number(c, "stop_fraction", self.stop_fraction, 0.0, 1.0, lo_open=True)
        _check_number(c, "min_leg_m", self.min_leg_m, 0.0, lo_open=True)
        _check_number(c, "merge_m", self.merge_m, 0.0)
        _check_number(c, "hazcam_handoff_m", self.hazcam_handoff_m, 0.0, lo_open=True)
        _check_number(c, "pancam_handoff_m", self.pancam_handoff_m, self.hazcam_handoff_m, lo_open=True,
                      lo_name="hazcam_handoff_m")
        for d in self.hazcam_stops_m:
            _check_number(c, "hazcam_stops_m[]", d, 0.0, lo_open=True)
        _check_number(c, "standoff_m", self.standoff_m, 0.0, lo_open=True, none_ok=True)
        _check_number(c, "standoff_step_m", self.standoff_step_m, 0.01)  # finer: hundreds of plans per bearing
        _check_number(c, "arm_margin_sigmas", self.arm_margin_sigmas, 0.0)
        if not self.detour_bearings_rad or self.detour_bearings_rad[0] != 0.0:
            raise ValueError(f"{c}.detour_bearings_rad: must start with 0.0 (the direct approach), "
                             f"got {self.detour_bearings_rad!r}")
        for b in self.detour_bearings_rad:
            _check_number(c, "detour_bearings_rad[]", b, -math.pi / 2, math.pi / 2)
        _check_number(c, "path_step_m", self.path_step_m, 0.0, lo_open=True)
        _check_number(c, "turn_step_rad", self.turn_step_rad, 0.0, lo_open=True)
        _check_number(c, "rock_height_m", self.rock_height_m, 0.0, lo_open=True)
        _check_number(c, "rock_cell_m", self.rock_cell_m, 0.0, lo_open=True)
        _check_number(c, "ground_window_m", self.ground_window_m, 0.0, lo_open=True)
        _check_number(c, "rock_keep_out_m", self.rock_keep_out_m, 0.0)
        _check_number(c, "target_keep_out_m", self.target_keep_out_m, 0.0)
        if not isinstance(self.fov_margin_px, dict):
            raise ValueError(f"{c}.fov_margin_px: expected a {{camera: px}} dict, got {self.fov_margin_px!r}")
        for cam, v in self.fov_margin_px.items():
            _check_number(c, f"fov_margin_px[{cam!r}]", v, 0, integer=True)
        _check_number(c, "other_fov_margin_px", self.other_fov_margin_px, 0, integer=True)
        self.arm.check()
        self.body.check()
        return self

    @property
    def final_distance_m(self) -> float:
        return self.arm.centre_m if self.standoff_m is None else float(self.standoff_m)

    def fov_margin(self, camera: str) -> int:
        """The field-of-view margin (px) of ``camera``."""
        return self.fov_margin_px.get(camera, self.other_fov_margin_px)


@dataclass(frozen=True)
class UncertaintyParams:
    """Pose-estimate error model for the Monte Carlo (1-sigma, per stop, relative to the previous stop).

    ``sigma_position_m`` / ``sigma_yaw_rad``: the per-stop noise of the rover's
    pose estimate relative to the previous stop; ``None`` takes the defaults
    (not the downlinked pose's absolute sigma: see
    :func:`~scipctl.pipeline.predict.from_downlink.sigmas_for`). Each leg adds ``drive_error_frac`` x leg length (m)
    and ``yaw_error_rad_per_m`` x leg length in quadrature. The target's 3-D
    re-estimate at each stop has range noise ``r^2 sigma_d / (f b)``.
    """

    sigma_position_m: Optional[float] = None
    sigma_yaw_rad: Optional[float] = None
    default_sigma_position_m: float = 0.01
    default_sigma_yaw_rad: float = math.radians(0.5)
    drive_error_frac: float = 0.05  # wheel odometry: a few % of the distance driven
    yaw_error_rad_per_m: float = math.radians(1.0)  # heading drift per metre
    disparity_sigma_px: float = 0.25
    n_samples: int = 1000
    n_track_samples: int = 8
    seed: int = 0

    def check(self) -> "UncertaintyParams":
        """Raise ValueError naming the first bad field; return self."""
        c = "UncertaintyParams"
        _check_number(c, "sigma_position_m", self.sigma_position_m, 0.0, none_ok=True)
        _check_number(c, "sigma_yaw_rad", self.sigma_yaw_rad, 0.0, none_ok=True)
        _check_number(c, "default_sigma_position_m", self.default_sigma_position_m, 0.0)
        _check_number(c, "default_sigma_yaw_rad", self.default_sigma_yaw_rad, 0.0)
        _check_number(c, "drive_error_frac", self.drive_error_frac, 0.0)
        _check_number(c, "yaw_error_rad_per_m", self.yaw_error_rad_per_m, 0.0)
        _check_number(c, "disparity_sigma_px", self.disparity_sigma_px, 0.0)
        _check_number(c, "n_samples", self.n_samples, 1, integer=True)
        _check_number(c, "n_track_samples", self.n_track_samples, 0, integer=True)
        _check_number(c, "seed", self.seed, 0, integer=True)
        return self

    def per_stop_sigmas(self) -> tuple:
        """``(sigma_position_m, sigma_yaw_rad)`` the Monte Carlo runs with: the parameters, else the defaults."""
        sp = self.default_sigma_position_m if self.sigma_position_m is None else self.sigma_position_m
        sy = self.default_sigma_yaw_rad if self.sigma_yaw_rad is None else self.sigma_yaw_rad
        return float(sp), float(sy)


ROUTES = ("plan", "downlink")


@dataclass(frozen=True)
class PredictParams:
    """Everything the prediction is run with (:func:`run_prediction`, :func:`predict_target`)."""

    approach: ApproachParams = field(default_factory=ApproachParams)
    uncertainty: UncertaintyParams = field(default_factory=UncertaintyParams)
    render_width_px: int = 256  # nominal expected views (for reports)
    stereo_downsample: int = 2
    max_edge_ratio: float = 20.0  # grid-mesh edge longer than this x its angular footprint: a depth discontinuity
    min_edge_m: float = 0.03
    smooth_sigma_px: float = 1.5  # stereo grids are smoothed along their rays before meshing (smooth_grid)
    occlusion_tol_m: float = 0.04
    low_texture_std: float = 0.015  # std of the expected window (0..1 units) below which texture is "low"
    min_coverage: float = 0.6  # fraction of the expected window the terrain covers
    max_incidence_rad: float = math.radians(85.0)  # grazing view of the target surface
    max_foreshortening_change: float = 2.0  # cos(incidence) ratio between consecutive images of the chain
    risk_probability: float = 0.9  # a stop/handoff whose probability is below this is at risk
    run_chain: bool = True
    search_margin_px: float = 40.0  # chain sim: rendered search region = true offset + this (see docs)
    # a tracked pixel is accurate when it lies within success_m of the target on the surface (per camera; the
    # paper's goal is 1 cm at the hazcams), or within min_success_px; farther than lost_m the chain has lost it
    success_m: dict = field(default_factory=lambda: {"pancam": 0.02, "navcam": 0.02, "hazcam": 0.01})
    other_success_m: float = 0.01
    min_success_px: float = 1.0
    lost_m: float = 0.05
    # the chain simulation runs with the on-board chain's windows and the navcam->hazcam handoff's expected window
    chain: ChainParams = field(default_factory=ChainParams)
    handoff: HandoffParams = field(default_factory=HandoffParams)
    # which approach is predicted: "plan" (the planner's own, :func:`plan_approach`; what a sequence uplinks) or
    # "downlink" (the downlink's own later stops, :func:`~.route.route_from_downlink`; for validating the prediction
    # against the chain run over those stops)
    route: str = "plan"
    # Prediction.confidence calibrated against the chain by the packaged model of the route
    # (core/prediction_calibration.py; docs/sequence.md, "Calibrated against the chain"); False: the simulated P
    calibrate: bool = True
    # the tracker's reach in the Monte Carlo (montecarlo.TRACKER_REACHES): "image" for the plane chain, whose
    # feature-guided step matches the whole image (543 chain steps of 49 rendered downlinks: of the steps whose
    # pointing offset was beyond the search radius, 71 of 142 were still within 4 px, against 292 of 401 inside it;
    # docs/sequence.md, "The tracker's reach");
    # "search" bounds each view by ChainParams.search_radius_px (the NCC-only chain)
    tracker_reach: str = "image"

    def success_of(self, camera: str) -> float:
        """The accuracy goal (m, on the surface) of a tracked pixel in ``camera``."""
        return self.success_m.get(camera, self.other_success_m)

    def check(self) -> "PredictParams":
        """Raise ValueError naming the first bad field (nested ones too); return self."""
        c = "PredictParams"
        self.approach.check()
        self.uncertainty.check()
        _check_number(c, "render_width_px", self.render_width_px, 1, integer=True)
        _check_number(c, "stereo_downsample", self.stereo_downsample, 1, integer=True)
        _check_number(c, "max_edge_ratio", self.max_edge_ratio, 0.0, lo_open=True)
        _check_number(c, "min_edge_m", self.min_edge_m, 0.0)
        _check_number(c, "smooth_sigma_px", self.smooth_sigma_px, 0.0)
        _check_number(c, "occlusion_tol_m", self.occlusion_tol_m, 0.0)
        _check_number(c, "low_texture_std", self.low_texture_std, 0.0)
        _check_number(c, "min_coverage", self.min_coverage, 0.0, 1.0)
        _check_number(c, "max_incidence_rad", self.max_incidence_rad, 0.0, math.pi / 2, lo_open=True)
        _check_number(c, "max_foreshortening_change", self.max_foreshortening_change, 1.0)
        _check_number(c, "risk_probability", self.risk_probability, 0.0, 1.0)
        _check_number(c, "search_margin_px", self.search_margin_px, 0.0)
        if not isinstance(self.success_m, dict):
            raise ValueError(f"{c}.success_m: expected a {{camera: m}} dict, got {self.success_m!r}")
        for cam, v in self.success_m.items():
            _check_number(c, f"success_m[{cam!r}]", v, 0.0, lo_open=True)
        _check_number(c, "other_success_m", self.other_success_m, 0.0, lo_open=True)
        _check_number(c, "min_success_px", self.min_success_px, 0.0)
        _check_number(c, "lost_m", self.lost_m, 0.0, lo_open=True)
        self.chain.check()
        # the two HandoffParams fields the chain simulation uses (HandoffParams lives in core.handoff)
        _check_number(c, "handoff.template_half_px", self.handoff.template_half_px, 1, integer=True)
        _check_number(c, "handoff.search_radius_px", self.handoff.search_radius_px, 0.0, lo_open=True)
        if self.tracker_reach not in ("image", "search"):
            raise ValueError(f"{c}.tracker_reach: expected image or search, got {self.tracker_reach!r}")
        if self.route not in ROUTES:
            raise ValueError(f"{c}.route: expected one of {', '.join(ROUTES)}, got {self.route!r}")
        return self
